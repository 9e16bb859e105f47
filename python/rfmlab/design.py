"""What ``Study.design`` returns: the planned test (as ``rfmlab design``, docs/planning.md)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import polars as pl


@dataclass
class PlannedDesign:
    """One scored design: a drive point and the response sensors.

    Attributes:
        drive: id of the point where the shaker drives.
        sensors: the response sensors as ``"id +axis"`` (``"3 +y"``); ids of 100000 and
            above are generated candidate places (see ``Design.candidates`` for where).
        sd_rel: the predicted relative posterior sd ``sd(p) / p`` per model, level and
            parameter: ``sd_rel["model4"]["L1"]["E0"]`` (geometric mean over the parameter
            draws).
        worst_sd_rel: the largest of ``sd_rel`` (the design criterion).
        info_gain: the expected information gain (nats, summed over models and levels).
        own_masses: whether the sensor masses in the prediction were this design's own.
    """

    drive: int
    sensors: list[str]
    sd_rel: dict[str, dict[str, dict[str, float]]]
    worst_sd_rel: float
    info_gain: float
    own_masses: bool = True

    @classmethod
    def _from_native(cls, d: dict) -> "PlannedDesign":
        return cls(
            drive=int(d["drive"]),
            sensors=list(d["sensors"]),
            sd_rel={m: {lv: dict(ps) for lv, ps in lvs.items()} for m, lvs in d["sd_rel"].items()},
            worst_sd_rel=float(d["worst_sd_rel"]),
            info_gain=float(d["info_gain"]),
            own_masses=bool(d["own_masses"]),
        )

    def sd_rel_frame(self) -> pl.DataFrame:
        """``sd_rel`` in long form: one row per model, level and parameter."""
        rows = [
            (m, lv, p, v)
            for m, lvs in self.sd_rel.items()
            for lv, ps in lvs.items()
            for p, v in ps.items()
        ]
        return pl.DataFrame(
            rows,
            schema={"model": pl.String, "level": pl.String, "parameter": pl.String, "sd_rel": pl.Float64},
            orient="row",
        )


@dataclass
class Design:
    """The planned test.

    Attributes:
        best: the best design found.
        current: the study's own design (its measured points in their directions, its
            excitation), scored the same way; None when its points are not all candidate
            channels.
        table: the ranked designs as in ``design.parquet``: one row per design, model and
            level (``design`` is ``"current"``, ``"best"`` or ``"ranked"``), with
            ``sd_rel_<parameter>``, ``worst_sd_rel`` and ``info_gain``.
        candidates: every candidate channel as in ``design_candidates.parquet`` (place,
            face, position, direction, whether the best or the study's design holds it, the
            information it adds to the best design).
        notes: what the computation noted (reduced model, certificate, measurement model).
        report: the report (markdown, as ``report.md`` without the figure).
        models, levels, params: the models, levels and parameter names per model the
            prediction covers.
        timings: seconds per step.
        output: the folder written, or None.
    """

    best: PlannedDesign
    current: PlannedDesign | None
    table: pl.DataFrame
    candidates: pl.DataFrame
    notes: list[str]
    report: str
    models: list[str] = field(default_factory=list)
    levels: list[str] = field(default_factory=list)
    params: dict[str, list[str]] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    output: Path | None = None

    def __repr__(self) -> str:
        return (
            f"<rfmlab.Design: best drive {self.best.drive}, sensors {self.best.sensors}, "
            f"worst sd {self.best.worst_sd_rel:.3g}>"
        )
