"""Data shipped with the package: a small motion sample and pretrained models."""

from __future__ import annotations

from pathlib import Path

DATA_DIR = Path(__file__).parent
SAMPLE_DIR = DATA_DIR / "sample"
MODELS_DIR = DATA_DIR / "models"


def shared_data_dir() -> Path | None:
    """``../shared/data/bandai-namco-2`` beside a source checkout, when present."""
    for base in (Path.cwd(), *Path.cwd().parents[:2], Path(__file__).resolve().parents[4]):
        cand = base / "shared" / "data" / "bandai-namco-2"
        if cand.is_dir():
            return cand
        cand = base.parent / "shared" / "data" / "bandai-namco-2"
        if cand.is_dir():
            return cand
    return None
