"""Shared helpers of the Python package's tests: study files rewritten into a temporary folder
(absolute data paths, their own output folder), the rfmlab CLI binary, and one short Bayesian
run (Model 4 at L1, NUTS) that several tests read."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
STUDIES = REPO / "studies"


def study_copy(tmp: Path, base: str, name: str, edits: dict[str, str] | None = None) -> Path:
    """``studies/<base>`` written to ``tmp/<name>.toml`` with its data paths absolute, its own
    name and output folder ``tmp/results/<name>``, and ``edits`` (exact text -> replacement)."""
    text = (STUDIES / base).read_text()
    text = re.sub(r'^name = "[^"]*"', f'name = "{name}"\noutput_dir = "{tmp / "results" / name}"',
                  text, count=1, flags=re.M)
    text = text.replace('"data/', f'"{STUDIES / "data"}/')
    for old, new in (edits or {}).items():
        assert old in text, f"{old!r} not in studies/{base}"
        text = text.replace(old, new)
    path = tmp / f"{name}.toml"
    path.write_text(text)
    return path


def drop_section(text: str, header: str) -> str:
    """``text`` without the TOML section ``header`` (up to the next section)."""
    i = text.find(header)
    if i < 0:
        return text
    j = text.find("\n[", i + 1)
    return text[:i] + (text[j + 1:] if j >= 0 else "")


def cli_binary() -> Path:
    """The rfmlab binary: $RFMLAB_BIN, else target/debug or target/release of the repository
    (`cargo test` and `cargo build` put it there)."""
    env = os.environ.get("RFMLAB_BIN")
    candidates = [Path(env)] if env else [REPO / "target" / "debug" / "rfmlab",
                                           REPO / "target" / "release" / "rfmlab"]
    for c in candidates:
        if c.is_file():
            return c
    found = shutil.which("rfmlab")
    if found:
        return Path(found)
    pytest.fail(f"no rfmlab binary (tried {candidates}; build it with `cargo build` or set RFMLAB_BIN)")


# A short Bayesian study: Model 4 (the truth's law) at L1 over 10-60 Hz, NUTS 4 x (300 + 500).
BAYES_EDITS = {
    'models = ["model3", "model4", "model5"]': 'models = ["model4"]',
    'levels = ["L1", "L2"]': 'levels = ["L1"]',
    'samplers = ["nuts", "stepping_stone"]': 'samplers = ["nuts"]',
    "band_hz = [1.0, 500.0]": "band_hz = [10.0, 60.0]",
    "tune = 1000": "tune = 300",
    "draws = 1000": "draws = 500",
    "starts = 8": "starts = 2",
    "sensitivity = false": "sensitivity = false\nfigures = false",
}


@pytest.fixture(scope="session")
def bayes_study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bayes")
    path = study_copy(tmp, "bayes.toml", "py_bayes", BAYES_EDITS)
    text = path.read_text()
    for sec in ("[inference.stepping_stone]", "[inference.across_levels]"):
        text = drop_section(text, sec)
    path.write_text(text)
    return path


@pytest.fixture(scope="session")
def bayes_run(bayes_study):
    import rfmlab

    study = rfmlab.load(bayes_study)
    return study, study.run(rom_cache=False)
