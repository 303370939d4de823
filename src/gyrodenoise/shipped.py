"""The shipped models from the command line: what each is, and its model card.

    python -m gyrodenoise.shipped            # one line per shipped model
    python -m gyrodenoise.shipped euroc      # its model card (src/gyrodenoise/weights/<card>.md)

A card covers a family (`tumvi.md`: tumvi, tumvi-calibrated and tumvi-denoiser): a name without its own card shows
the card of the name before its first '-'.
"""

from __future__ import annotations

# ruff: noqa: E402
# (the imports follow the hand-over below)
if __name__ == "__main__":  # python -m gyrodenoise.shipped: a Ctrl-C during the imports below ends in one line
    from gyrodenoise.launch import run_as_main

    run_as_main("shipped")  # imports this module as gyrodenoise.shipped and runs its main

import argparse
import sys
from pathlib import Path

from gyrodenoise.pretrained import available_models, load_model, model_rate, sensor_model, shipped_dir


def card_path(name: str) -> Path | None:
    """The model card of a shipped model: its own, else its family's; None when there is none."""
    for stem in (name, name.split("-", 1)[0]):
        if (path := shipped_dir() / f"{stem}.md").is_file():
            return path
    return None


def summary_line(name: str) -> str:
    """'euroc: ensemble of 8 networks, euroc (ADIS16448) at 200 Hz, ...' from the model file's metadata."""
    model, meta = load_model(name, warn=False)
    members = getattr(model, "members", None)
    kind = meta["model"].get("name", "?")
    what = f"ensemble of {len(members)}" if members is not None else kind
    rate = model_rate(meta)
    trained = f"{meta.get('dataset', '?')} ({sensor_model(meta) or 'sensor not recorded'})"
    trained += f" at {rate:.4g} Hz" if rate else ""
    verdict = {True: "beat the calibrated model", False: "did NOT beat the calibrated model", None: "not compared"}
    val = meta.get("val_aoe_deg")
    if kind == "calibrated":  # the baseline itself
        what, compared = "12-parameter calibrated model", ""
    else:
        compared = f"; {verdict.get(meta.get('beats_calibrated'), 'not compared')} in validation"
    return f"{name}: {what}, trained on {trained}{compared}" + (
        f" (validation AOE {val:.2f} deg)" if isinstance(val, int | float) else ""
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m gyrodenoise.shipped",
        description="List the shipped models (loadable by name in evaluate, correct, export), or print one's card.",
    )
    ap.add_argument("name", nargs="?", help="a shipped model's name: print its model card")
    args = ap.parse_args(argv)
    names = available_models()
    if args.name is None:
        for name in names:
            print(summary_line(name))
        print("model card of one: python -m gyrodenoise.shipped NAME")
        return 0
    if args.name not in names:
        print(f"error: no shipped model {args.name!r}; shipped: {', '.join(names)}", file=sys.stderr)
        return 2
    card = card_path(args.name)
    print(card.read_text() if card else f"{summary_line(args.name)}\n(no model card ships with it)")
    return 0
