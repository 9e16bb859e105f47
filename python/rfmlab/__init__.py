"""rfmlab from Python: identify viscoelastic constitutive models of adhesives in bonded joints
from measured FRFs.

    import rfmlab
    study = rfmlab.load("studies/default.toml")      # validated; errors raise rfmlab.StudyError
    results = study.run()                            # in memory; output="dir" also writes files
    results.tables["parameters"]                     # every table as a polars DataFrame
    idata = results.to_inference_data(model="model4", level="L1")   # ArviZ
    post = study.posterior("model4", "L1")           # logp(x), logp_and_grad(x) for other samplers
    plan = study.design(output="plan")               # where the sensors go (rfmlab design)

See docs/python.md for the whole API.
"""

from __future__ import annotations

import io
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import polars as pl

from . import _rfmlab
from ._errors import DataError, RfmlabError, RunError, StudyError
from .design import Design, PlannedDesign
from .posterior import Posterior
from .results import Results

__all__ = [
    "load",
    "read_uff",
    "simulate",
    "modulus",
    "law_parameters",
    "Study",
    "Results",
    "Posterior",
    "Design",
    "PlannedDesign",
    "Simulation",
    "RfmlabError",
    "StudyError",
    "DataError",
    "RunError",
]
__version__ = _rfmlab.__version__

log = logging.getLogger("rfmlab")


class Study:
    """A validated study file (``rfmlab.load``)."""

    def __init__(self, native: _rfmlab.Study):
        self._native = native

    name = property(lambda self: self._native.name, doc="The study's name (`[study] name`).")
    description = property(lambda self: self._native.description)
    file = property(lambda self: Path(self._native.file), doc="The study file.")
    output_dir = property(
        lambda self: Path(self._native.output_dir),
        doc="Where `rfmlab run` writes (the study's `[study] output`, default results/<name>).",
    )
    seed = property(lambda self: self._native.seed)
    models = property(lambda self: list(self._native.models), doc="`[[models]]` names.")
    levels = property(lambda self: list(self._native.levels), doc="Measurement level names.")

    @property
    def inference(self) -> dict | None:
        """`[inference]` models and levels, or None when the study has no such section."""
        i = self._native.inference
        return None if i is None else {"models": list(i[0]), "levels": list(i[1])}

    def __repr__(self) -> str:
        return f"<rfmlab.Study {self.name!r} from {str(self.file)!r}: models {self.models}, levels {self.levels}>"

    def check(self) -> dict:
        """Check the study without running it (data files, channels, band, initial values)."""
        return json.loads(self._native.check())

    def run(
        self,
        output: str | Path | None = None,
        quiet: bool = True,
        progress: Callable[[str, int, int], object] | None = None,
        figures: bool = True,
        rom_cache: bool = True,
        closed_loop: bool | None = None,
    ) -> Results:
        """Run the study in memory and return its Results.

        Args:
            output: a folder to also write the results into (parquet tables, figures,
                report.md, manifest.json, replaced atomically as by ``rfmlab run``); None
                writes nothing.
            quiet: when False, each step is logged at INFO on the ``rfmlab`` logger (at DEBUG
                otherwise).
            progress: called as ``progress(step, done, total)`` on every progress event
                (``total`` 0 when the step's length is unknown); an exception in it stops
                the run and is raised.
            figures: draw figures when writing to ``output`` (as the study's
                ``analyses.figures`` allows).
            rom_cache: reuse a certified ROM from ``.rom-cache/`` beside the study's output
                folder (as ``rfmlab run``; False builds and certifies it again).
            closed_loop: run the closed loop after the inference (True; with the study's
                ``[closed_loop]`` settings, else the defaults), skip it (False), or as the
                study says (None). Its tables are ``closed_loop/<name>`` in ``tables``.

        The GIL is released while the pipeline runs; Ctrl-C stops it (KeyboardInterrupt).
        """
        level = logging.INFO if not quiet else logging.DEBUG
        last = [None]

        def callback(step: str, done: int, total: int) -> None:
            if step != last[0]:
                last[0] = step
                log.log(level, "%s", step)
            if progress is not None:
                progress(step, done, total)

        names, blobs, files, loop = self._native._run(
            None if output is None else str(output), callback, figures, rom_cache, closed_loop
        )
        tables = {n: pl.read_parquet(io.BytesIO(b)) for n, b in zip(names, blobs)}
        return Results(
            tables,
            study=self,
            files=list(files),
            output=output,
            closed_loop=None if loop is None else json.loads(loop),
        )

    def diagnose(
        self,
        model: str | None = None,
        threshold_nats: float | None = None,
        output: str | Path | None = None,
        quiet: bool = True,
        progress: Callable[[str, int, int], object] | None = None,
    ) -> dict:
        """Run the closed loop (as ``rfmlab diagnose``) and return its summary.

        The loop fits ``model`` (default: the first ``[inference]`` model), tests candidate
        effects the study does not declare (point masses, gains, a beam factor, extra
        Maxwell branches, the fractional Zener law...), accepts those whose Laplace evidence
        gain exceeds ``threshold_nats`` (default: the study's ``[closed_loop]
        evidence_threshold``, else 5) and refits. The summary (a dict) has per level the
        conclusion, the accepted effects (name, type, size, sd), the normalised chi-square,
        relative residual norm and FRAC before and after, and every parameter before and
        after with its sd and the truth (for simulated data).

        With ``output`` (a folder) its tables, report and figures are written there; without
        it they go to a temporary folder that is removed. Progress messages go to the
        ``rfmlab`` logger (INFO with ``quiet=False``) and to ``progress(message, 0, 0)``.
        Ctrl-C is honoured when the loop finishes (it has no cancellation point).
        """
        level = logging.INFO if not quiet else logging.DEBUG

        def callback(step: str, done: int, total: int) -> None:
            log.log(level, "%s", step)
            if progress is not None:
                progress(step, done, total)

        text = self._native._diagnose(
            model, threshold_nats, None if output is None else str(output), output is not None, callback
        )
        return json.loads(text)

    def design(
        self,
        output: str | Path | None = None,
        sensors: int | None = None,
        force: bool = False,
        quiet: bool = True,
        progress: Callable[[str, int, int], object] | None = None,
    ) -> Design:
        """Plan the test (as ``rfmlab design``, docs/planning.md) and return the Design.

        The study's ``[design]`` section sets the search (its defaults when the study has
        none): where the response sensors go, in which directions, where the shaker drives,
        so that the planned measurement pins down the adhesive law's parameters. The study's
        own design is scored the same way (``Design.current``).

        Args:
            output: a folder to also write the design's files into (``design.parquet``,
                ``design_candidates.parquet``, a figure, ``report.md``, ``manifest.json``,
                replaced as a whole as by ``rfmlab design -o``); None writes nothing.
            sensors: response sensors per design (overrides ``[design] sensors``).
            force: replace ``output`` even when rfmlab did not write it (a folder with other
                files, or a file), as ``--force``.
            quiet: when False, each step is logged at INFO on the ``rfmlab`` logger (at DEBUG
                otherwise).
            progress: called as ``progress(message, 0, 0)`` on every step.

        A wrong ``[design]`` or ``sensors`` (or a study the design cannot use, e.g. a level
        without ``force_rms_n``) raises StudyError; an output folder that may not be
        replaced, or a failed computation, RunError. The GIL is released while it computes;
        Ctrl-C is honoured when the search ends (it has no cancellation point).
        """
        level = logging.INFO if not quiet else logging.DEBUG

        def callback(step: str, done: int, total: int) -> None:
            log.log(level, "%s", step)
            if progress is not None:
                progress(step, done, total)

        d = self._native._design(None if output is None else str(output), sensors, force, callback)
        return Design(
            best=PlannedDesign._from_native(d["best"]),
            current=None if d["current"] is None else PlannedDesign._from_native(d["current"]),
            table=pl.read_parquet(io.BytesIO(d["table"])),
            candidates=pl.read_parquet(io.BytesIO(d["candidates"])),
            notes=list(d["notes"]),
            report=d["report"],
            models=list(d["models"]),
            levels=list(d["levels"]),
            params={m: list(p) for m, p in zip(d["models"], d["params"])},
            timings={k: float(v) for k, v in d["timings"]},
            output=None if output is None else Path(output),
        )

    def posterior(
        self,
        model: str,
        level: str,
        at: Sequence[float] | dict | None = None,
        rom_cache: bool = True,
    ) -> Posterior:
        """The posterior of ``model`` at ``level`` over unconstrained coordinates.

        The density is the one rfmlab's samplers see (same data, forward model, noise model
        and priors). With a declared H1 estimator the run's samplers see the measurement
        bias linearised at the MAP: pass ``at`` (physical values of every coordinate, a
        sequence in the order of ``Posterior.names`` or a dict by name, e.g.
        ``results.map_point(model, level)``) to get exactly that density; without ``at``
        the exact measurement model is used. The first call builds the study's model and
        FRF engine (kept for later calls).
        """
        if isinstance(at, dict):
            # Names are only known once built: build without `at`, then again with it.
            names = self._native._posterior(model, level, None, rom_cache).names
            missing = [n for n in names if n not in at]
            if missing:
                raise KeyError(f"`at` lacks {missing}; the coordinates are {names}")
            at = [float(at[n]) for n in names]
        native = self._native._posterior(
            model, level, None if at is None else [float(v) for v in at], rom_cache
        )
        return Posterior(native)


def load(path: str | Path) -> Study:
    """Load and validate a study file; errors raise StudyError (file, key, message, fix)."""
    return Study(_rfmlab.load(str(path)))


def _frf_frame(cols: dict) -> pl.DataFrame:
    return pl.DataFrame(
        cols,
        schema={
            "level": pl.String,
            "quantity": pl.String,
            "response_id": pl.UInt32,
            "response_dir": pl.String,
            "reference_id": pl.UInt32,
            "reference_dir": pl.String,
            "freq_hz": pl.Float64,
            "re": pl.Float64,
            "im": pl.Float64,
            "coherence": pl.Float64,
        },
    )


def read_uff(path: str | Path) -> pl.DataFrame:
    """Read FRFs (and their coherences) from a UFF58 file into a long polars frame.

    One row per level, channel and line: level, quantity (receptance / mobility /
    accelerance, SI), response_id, response_dir, reference_id, reference_dir, freq_hz (Hz),
    re, im (the FRF in SI units of ``quantity``), coherence (null when not measured),
    force_rms_n and n_averages (null when the file does not state them).
    """
    cols, meta = _rfmlab.read_uff(str(path))
    df = _frf_frame(cols)
    lv = pl.DataFrame(
        {
            "level": list(meta.keys()),
            "force_rms_n": [m[0] for m in meta.values()],
            "n_averages": [m[1] for m in meta.values()],
        },
        schema={"level": pl.String, "force_rms_n": pl.Float64, "n_averages": pl.UInt32},
    )
    return df.join(lv, on="level", how="left", maintain_order="left")


@dataclass
class Simulation:
    """Virtual data from ``rfmlab.simulate``.

    Attributes:
        data: the simulated H1 and coherence, a frame like ``read_uff``'s (accelerance).
        truth: the truth as in the ``.truth.json`` sidecar (law and parameters per level,
            the chain's settings, structural effects), with ``notes`` on the engine.
        files: the UFF58 files and the sidecar written (when ``out`` was given).
    """

    data: pl.DataFrame
    truth: dict
    files: list[str] = field(default_factory=list)


def simulate(experiment: str | Path, out: str | Path | None = None) -> Simulation:
    """Simulate the virtual experiment of an experiment file (as ``rfmlab simulate``).

    With ``out`` (e.g. ``"data/virtual.uff"``) also writes ``<stem>_<level>.uff`` per level
    and ``<stem>.truth.json``, as the command does with ``--out``.
    """
    cols, truth, files = _rfmlab.simulate(str(experiment), None if out is None else str(out))
    return Simulation(_frf_frame(cols), json.loads(truth), list(files))


def law_parameters(model: str, branches: int | None = None) -> list[tuple[str, str]]:
    """(name, SI unit) of each parameter of a constitutive law (``"model4"``, ...)."""
    names, units = _rfmlab.law_parameters(model, branches)
    return list(zip(names, units))


def modulus(
    model: str,
    params: Sequence[float] | dict,
    freq_hz: Sequence[float] | np.ndarray,
    branches: int | None = None,
) -> np.ndarray:
    """E*(f) = E'(f) + j E''(f) in Pa of a constitutive law at ``freq_hz`` (complex array).

    ``params`` in SI units, in the law's order (``law_parameters``) or as a dict by name.
    """
    if isinstance(params, dict):
        params = [float(params[n]) for n, _ in law_parameters(model, branches)]
    f = np.asarray(freq_hz, dtype=np.float64)
    re, im = _rfmlab.modulus(model, [float(p) for p in params], f.ravel().tolist(), branches)
    return (np.asarray(re) + 1j * np.asarray(im)).reshape(f.shape)
