"""The notebooks in notebooks/: committed without outputs, and each runs end to end on small settings.

Each notebook is executed with nbclient in a temporary working directory, with GYRODENOISE_NB_SMALL=1
(tiny settings, well under a minute each on 2 CPU cores). Run one by hand with
`GYRODENOISE_NB_SMALL=1 python -m pytest -q tests/test_notebooks.py -k quickstart`, or all of them with
`GYRODENOISE_NB_SMALL=1 python -m pytest --nbmake notebooks/`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import nbclient
import nbformat
import pytest
from conftest import REPO, require_data
from nbclient.exceptions import CellExecutionError

NOTEBOOKS = REPO / "notebooks"
EXPECTED = ("01_quickstart_sim.ipynb", "02_euroc_table1.ipynb", "03_discrepancy.ipynb")
TIMEOUT_S = 300  # per cell; the whole notebook takes well under a minute with SMALL settings


def committed_notebooks() -> list[Path]:
    return sorted(NOTEBOOKS.glob("*.ipynb"))


def test_expected_notebooks_exist() -> None:
    names = {p.name for p in committed_notebooks()}
    missing = sorted(set(EXPECTED) - names)
    assert not missing, f"notebooks missing from {NOTEBOOKS}: {missing}"


@pytest.mark.parametrize("path", committed_notebooks(), ids=lambda p: p.name)
def test_notebook_has_no_outputs(path: Path) -> None:
    """Notebooks are kept stripped in git (nbstripout-style): no outputs, no execution counts."""
    nb = json.loads(path.read_text(encoding="utf-8"))
    dirty = []
    for i, cell in enumerate(nb.get("cells", [])):
        if cell.get("cell_type") != "code":
            continue
        if cell.get("outputs"):
            dirty.append(f"cell {i}: {len(cell['outputs'])} output(s)")
        if cell.get("execution_count") is not None:
            dirty.append(f"cell {i}: execution_count={cell['execution_count']}")
    assert not dirty, (
        f"{path.relative_to(REPO)} is committed with outputs ({'; '.join(dirty)}). Strip them before committing, "
        f"e.g. `nbstripout {path.relative_to(REPO)}` (pip install nbstripout)."
    )


def _weights_missing(*names: str) -> list[str]:
    from gyrodenoise.pretrained import shipped_dir

    return [n for n in names if not (shipped_dir() / f"{n}.pt").is_file()]


def _execute(path: Path, workdir: Path) -> float:
    """Run every cell in a fresh kernel with the small settings; returns the wall time (s)."""
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        timeout=TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(workdir)}},
    )
    start = time.time()
    try:
        client.execute()
    except CellExecutionError as err:
        pytest.fail(f"{path.relative_to(REPO)} failed (working directory {workdir}):\n{err}", pytrace=False)
    return time.time() - start


@pytest.fixture
def small_settings(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """The kernel inherits this environment: the small settings and the test's GYRODENOISE_CACHE."""
    monkeypatch.setenv("GYRODENOISE_NB_SMALL", "1")
    workdir = tmp_path / "work"
    workdir.mkdir()
    return workdir


def test_quickstart_sim_notebook(small_settings: Path) -> None:
    wall = _execute(NOTEBOOKS / "01_quickstart_sim.ipynb", small_settings)
    assert list((small_settings / "outputs" / "notebooks" / "01_quickstart").glob("*/model.pt")), (
        f"the quick-start notebook ran ({wall:.0f} s) but wrote no model.pt under {small_settings}"
    )


def test_euroc_table1_notebook(small_settings: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = require_data("euroc")
    missing = _weights_missing("euroc", "euroc-calibrated")
    if missing:
        pytest.skip(f"shipped EuRoC weights not in this install yet: {missing} (gyrodenoise/weights/<name>.pt)")
    monkeypatch.setenv("GYRODENOISE_DATA", str(data.parent))
    wall = _execute(NOTEBOOKS / "02_euroc_table1.ipynb", small_settings)
    tables = list((small_settings / "outputs" / "notebooks" / "02_euroc_table1").glob("*/table.md"))
    assert tables, f"the EuRoC notebook ran ({wall:.0f} s) but wrote no table.md under {small_settings}"
    assert "proposed" in tables[0].read_text()


def test_discrepancy_notebook(small_settings: Path) -> None:
    wall = _execute(NOTEBOOKS / "03_discrepancy.ipynb", small_settings)
    reports = list((small_settings / "outputs" / "notebooks" / "03_discrepancy").glob("*/report/report.json"))
    assert reports, f"the discrepancy notebook ran ({wall:.0f} s) but wrote no report.json under {small_settings}"
    named = {e["name"] for e in json.loads(reports[0].read_text())["named_effects"]}
    assert {"scale_factor", "time_offset"} <= named, f"the hidden effects were not both named: {sorted(named)}"


def test_notebooks_read_the_small_switch() -> None:
    """Every notebook reads GYRODENOISE_NB_SMALL, so the test settings above really are small."""
    for path in committed_notebooks():
        text = path.read_text(encoding="utf-8")
        assert "GYRODENOISE_NB_SMALL" in text, f"{path.name} ignores GYRODENOISE_NB_SMALL"
