"""Results of a study run: every table as a polars DataFrame, and ArviZ InferenceData."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import polars as pl

if TYPE_CHECKING:  # pragma: no cover
    import arviz

    from . import Study

# Columns of the draws table that are not parameters.
_DRAW_KEYS = ["level", "model", "sampler", "chain", "draw"]
_STATS = ["lp", "log_lik", "log_prior", "step_size", "tree_depth", "n_steps", "diverging", "energy"]


def _columns(df: pl.DataFrame) -> dict[str, str]:
    """Column names by their lower-case form (the draws table writes parameters lower-case)."""
    return {c.lower(): c for c in df.columns}


class Results:
    """What ``Study.run`` returns.

    Attributes:
        tables: every result table by name (``"parameters"``, ``"summary"``, ``"draws"``,
            ...; the tables and columns are those of the parquet files ``rfmlab run`` writes,
            see docs/outputs.md), as polars DataFrames.
        files: the files written (relative to ``output``) when the run was asked to write.
        output: the folder written, or None.
        closed_loop: the closed loop's summary when the run included it (per level: the
            conclusion, accepted effects, chi-square, residual norm and FRAC before and
            after, every parameter before and after with the truth), else None. Its tables
            are ``tables["closed_loop/closed_loop"]`` (before/after per quantity) and
            ``tables["closed_loop/candidates"]``.
    """

    def __init__(
        self,
        tables: dict[str, pl.DataFrame],
        study: "Study | None" = None,
        files: list[str] | None = None,
        output: str | Path | None = None,
        closed_loop: dict | None = None,
    ):
        self.tables = tables
        self.study = study
        self.files = files or []
        self.output = None if output is None else Path(output)
        self.closed_loop = closed_loop

    def __repr__(self) -> str:
        name = self.study.name if self.study is not None else "?"
        return f"<rfmlab.Results of {name!r}: tables {sorted(self.tables)}>"

    def table(self, name: str) -> pl.DataFrame:
        """The table ``name``; a KeyError lists the tables present."""
        try:
            return self.tables[name]
        except KeyError:
            raise KeyError(
                f"no table {name!r} in these results; present: {sorted(self.tables)}"
                " (the Bayesian tables need an [inference] section in the study)"
            ) from None

    # The common tables by name.
    parameters = property(lambda self: self.table("parameters"), doc="Identified parameters (RFM), per level and model.")
    frf = property(lambda self: self.table("frf"), doc="Measured, initial and updated FRFs.")
    modulus = property(lambda self: self.table("modulus"), doc="E'(f), E''(f) per level and source.")
    correlation = property(lambda self: self.table("correlation"), doc="FRAC per channel.")
    modal = property(lambda self: self.table("modal"), doc="Circle fit, IEM and band-constant results.")
    summary = property(lambda self: self.table("summary"), doc="Posterior summary with R-hat, ESS, MCSE.")
    draws = property(lambda self: self.table("draws"), doc="Posterior draws per sampler.")
    laplace = property(lambda self: self.table("laplace"), doc="MAP and Laplace approximation.")
    evidence = property(lambda self: self.table("evidence"), doc="Log evidence per estimator.")
    model_comparison = property(lambda self: self.table("model_comparison"), doc="Bayes factors, LOO, WAIC, FRAC bands.")
    pointwise_loglik = property(lambda self: self.table("pointwise_loglik"), doc="Log likelihood per line and draw.")

    # --- typed helpers -------------------------------------------------------------------

    def map_point(self, model: str, level: str) -> dict[str, float]:
        """The MAP (physical values, SI) of every coordinate of ``model`` at ``level``, in the
        posterior's order: what ``Study.posterior(..., at=...)`` takes."""
        t = self.laplace.filter((pl.col("level") == level) & (pl.col("model") == model))
        if t.height == 0:
            raise KeyError(f"no MAP of {model} at {level} in the laplace table")
        return dict(zip(t["parameter"].to_list(), t["map"].to_list()))

    def _sampler(self, model: str, level: str, sampler: str | None) -> str:
        d = self.draws.filter((pl.col("level") == level) & (pl.col("model") == model))
        present = d["sampler"].unique(maintain_order=True).to_list()
        if not present:
            raise KeyError(f"no draws of {model} at {level}; the draws table has "
                           f"{self.draws.select('level', 'model').unique().rows()}")
        if sampler is None:
            return "nuts" if "nuts" in present else present[0]
        if sampler not in present:
            raise KeyError(f"no {sampler} draws of {model} at {level}; present: {present}")
        return sampler

    def posterior_draws(self, model: str, level: str, sampler: str | None = None) -> dict[str, np.ndarray]:
        """Draws per coordinate as (chain, draw) arrays (physical values, SI)."""
        sampler = self._sampler(model, level, sampler)
        d = self.draws.filter(
            (pl.col("level") == level) & (pl.col("model") == model) & (pl.col("sampler") == sampler)
        ).sort("chain", "draw")
        names = self._parameters(model, level, sampler)
        n_chain = d["chain"].n_unique()
        shape = (n_chain, d.height // n_chain)
        if shape[0] * shape[1] != d.height:
            raise ValueError(f"{sampler} draws of {model} at {level}: chains of unequal length")
        col = _columns(d)
        return {p: d[col[p.lower()]].to_numpy().reshape(shape) for p in names}

    def _parameters(self, model: str, level: str, sampler: str) -> list[str]:
        s = self.summary.filter(
            (pl.col("level") == level) & (pl.col("model") == model) & (pl.col("sampler") == sampler)
        )
        return s["parameter"].to_list()

    # --- ArviZ ---------------------------------------------------------------------------

    def to_inference_data(
        self,
        model: str,
        level: str,
        sampler: str | None = None,
        loo_draws: bool = False,
        prior_draws: int = 1000,
    ) -> "arviz.InferenceData":
        """The posterior of ``model`` at ``level`` as ArviZ InferenceData.

        Groups:
            posterior: one variable per coordinate (physical values, SI), dims (chain, draw);
            sample_stats: lp, log_lik, log_prior (nats, per draw) and the NUTS statistics (step_size,
                tree_depth, n_steps, diverging, energy) when present;
            log_likelihood: ``frf``, the log likelihood per frequency line (summed over
                channels), dims (chain, draw, freq_hz): on the thinned draws the
                ``model_comparison`` table's PSIS-LOO and WAIC used (their draw
                coordinates are those of the posterior);
            observed_data: ``accelerance_re``, ``accelerance_im`` ((m/s^2)/N), dims
                (channel, freq_hz), the measured FRFs in the band;
            prior: ``prior_draws`` draws from the prior (needs the study's engine: built
                once per study; 0 leaves the group out);
            constant_data: ``map``, ``laplace_sd`` and ``truth`` (NaN when unknown), dim
                parameter.

        ``sampler``: "nuts" when it ran, else the first present. ``loo_draws=True`` keeps only
        the draws of the log_likelihood group in posterior and sample_stats, so that
        ``az.loo`` uses the same draws (and relative efficiency) as the ``model_comparison``
        table and gives the same numbers.
        """
        import arviz as az
        import xarray as xr

        sampler = self._sampler(model, level, sampler)
        names = self._parameters(model, level, sampler)
        d = self.draws.filter(
            (pl.col("level") == level) & (pl.col("model") == model) & (pl.col("sampler") == sampler)
        ).sort("chain", "draw")
        chains = d["chain"].unique().sort().to_list()
        n_draw = d.height // len(chains)
        if n_draw * len(chains) != d.height:
            raise ValueError(f"{sampler} draws of {model} at {level}: chains of unequal length")
        draw_ids = d.filter(pl.col("chain") == chains[0])["draw"].to_numpy()

        keep = None
        pw = None
        if "pointwise_loglik" in self.tables:
            pw = self.pointwise_loglik.filter(
                (pl.col("level") == level) & (pl.col("model") == model) & (pl.col("sampler") == sampler)
            )
            if pw.height == 0:
                pw = None
        if pw is not None:
            pw_draws = pw.filter(pl.col("chain") == chains[0])["draw"].unique().sort().to_numpy()
            if loo_draws:
                keep = np.isin(draw_ids, pw_draws)
        elif loo_draws:
            raise KeyError(f"no pointwise log likelihood of {model} at {level} ({sampler})")

        cols = _columns(d)

        def cube(col: str, dtype=np.float64) -> np.ndarray:
            a = d[cols.get(col.lower(), col)].to_numpy().astype(dtype).reshape(len(chains), n_draw)
            return a if keep is None else a[:, keep]

        ids = draw_ids if keep is None else draw_ids[keep]
        coords = {"chain": chains, "draw": ids}
        posterior = xr.Dataset({p: (("chain", "draw"), cube(p)) for p in names}, coords=coords)
        stats = {}
        for s in _STATS:
            if s in d.columns and d[s].null_count() == 0 and not d[s].cast(pl.Float64).is_nan().any():
                stats[s] = (("chain", "draw"), cube(s, bool if s == "diverging" else np.float64))
        groups = {"posterior": posterior, "sample_stats": xr.Dataset(stats, coords=coords)}

        if pw is not None:
            pw = pw.sort("chain", "draw", "line")
            lines = pw.filter((pl.col("chain") == chains[0]) & (pl.col("draw") == pw_draws[0]))
            freq = lines.sort("line")["freq_hz"].to_numpy()
            n_line = len(freq)
            per_chain = pw.height // (len(chains) * n_line)
            ll = pw["log_lik"].to_numpy().reshape(len(chains), per_chain, n_line)
            groups["log_likelihood"] = xr.Dataset(
                {"frf": (("chain", "draw", "freq_hz"), ll)},
                coords={"chain": chains, "draw": pw_draws, "freq_hz": freq},
            )

        if "frf" in self.tables:
            m = self.frf.filter((pl.col("level") == level) & (pl.col("kind") == "measured"))
            if m.height:
                m = m.sort("response_id", "freq_hz")
                channels = m["response_id"].unique().sort().to_list()
                f = m.filter(pl.col("response_id") == channels[0])["freq_hz"].to_numpy()
                shape = (len(channels), len(f))
                groups["observed_data"] = xr.Dataset(
                    {
                        "accelerance_re": (("channel", "freq_hz"), m["accelerance_re"].to_numpy().reshape(shape)),
                        "accelerance_im": (("channel", "freq_hz"), m["accelerance_im"].to_numpy().reshape(shape)),
                    },
                    coords={"channel": channels, "freq_hz": f},
                )

        s = self.summary.filter(
            (pl.col("level") == level) & (pl.col("model") == model) & (pl.col("sampler") == sampler)
        )
        groups["constant_data"] = xr.Dataset(
            {
                c: (("parameter",), s[c].cast(pl.Float64).fill_null(np.nan).to_numpy())
                for c in ("map", "laplace_sd", "truth")
                if c in s.columns
            },
            coords={"parameter": s["parameter"].to_list()},
        )

        if prior_draws and self.study is not None:
            post = self.study.posterior(model, level)
            x = post.sample_prior(prior_draws, seed=self.study.seed)
            p = post.to_constrained(x)
            groups["prior"] = xr.Dataset(
                {n: (("chain", "draw"), p[None, :, k]) for k, n in enumerate(post.names)},
                coords={"chain": [0], "draw": np.arange(prior_draws)},
            )
        return az.InferenceData(**groups)
