"""Library notices that say nothing about a run are dropped; everything else Lightning says still gets through."""

import logging
import warnings

from gyrodenoise.notices import LIGHTNING_LOGGER, ONNX_REGISTRATION_LOGGER, quiet_library_notices


def test_only_the_named_notices_are_dropped(caplog):
    quiet_library_notices()
    quiet_library_notices()  # idempotent: one filter
    log = logging.getLogger(LIGHTNING_LOGGER)
    assert sum(type(f).__name__ == "_DropNoise" for f in log.filters) == 1
    with caplog.at_level(logging.INFO, logger=LIGHTNING_LOGGER):
        log.info("💡 Tip: For seamless cloud logging, try installing litlogger")
        log.info("Trainer already configured with model summary callbacks: [ModelSummary].")
        log.info("GPU available: False, used: False")
    assert [r.getMessage() for r in caplog.records] == ["GPU available: False, used: False"]
    # torch's loggers do not propagate to the root logger once torch.onnx is imported (it is, by the export tests),
    # so caplog cannot see them: listen on the exporter's logger itself (its filters run before its handlers)
    seen: list[str] = []
    listener = logging.Handler(logging.WARNING)
    listener.emit = lambda record: seen.append(record.getMessage())
    onnx_log = logging.getLogger(ONNX_REGISTRATION_LOGGER)
    onnx_log.addHandler(listener)
    try:
        onnx_log.warning("torchvision is not installed. Skipping torchvision::roi_align")
        onnx_log.warning("some other registration problem")
    finally:
        onnx_log.removeHandler(listener)
    assert seen == ["some other registration problem"]


def test_leafspec_deprecation_is_dropped_other_warnings_are_not():
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        quiet_library_notices()
        warnings.warn("`isinstance(treespec, LeafSpec)` is deprecated, use ...", FutureWarning, stacklevel=1)
        warnings.warn("something else is deprecated", FutureWarning, stacklevel=1)
    assert [str(w.message) for w in seen] == ["something else is deprecated"]
