"""Success by the episode's randomised factors: equal-count bins, an interval per bin.

Bin edges are quantiles of the observed factor values (`n_bins` equal-count bins, default 5),
taken at observed values and de-duplicated (ties can merge bins), so every bin holds episodes
and the intervals have similar widths whatever the factor's units or range; a factor that never
varies gets one bin. Bins are [low, high), the last one [low, high].
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.report import BreakdownRow
from openral_mjx.stats.intervals import wilson_interval


def quantile_edges(values: np.ndarray, n_bins: int) -> np.ndarray:
    """Edges of up to `n_bins` equal-count bins: the bins' distinct lower edges (observed
    values, increasing), then the largest value (which may equal the last lower edge)."""
    if n_bins < 1:
        raise ConfigError(f"factor_bins must be a positive integer, got {n_bins}")
    ordered = np.sort(np.asarray(values, np.float64))
    n = ordered.size
    # Bin i starts at the ceil(i n / n_bins)-th smallest value: counts differ by at most one.
    starts = np.minimum(np.ceil(np.arange(n_bins) * n / n_bins).astype(int), n - 1)
    return np.append(np.unique(ordered[starts]), ordered[-1])


def breakdown(
    factors: Mapping[str, np.ndarray],
    success: np.ndarray,
    n_bins: int = 5,
    confidence: float = 0.95,
) -> list[BreakdownRow]:
    """One row per (factor, bin), factors in the given order, bins in increasing order."""
    success = np.asarray(success, bool)
    rows = []
    for name, values in factors.items():
        values = np.asarray(values, np.float64)
        edges = quantile_edges(values, n_bins)
        # Bin i holds edges[i] <= v < edges[i+1]; the last bin also holds the maximum.
        index = np.minimum(np.searchsorted(edges, values, side="right") - 1, len(edges) - 2)
        for i, high in enumerate(edges[1:]):
            mask = index == i
            n, k = int(mask.sum()), int(success[mask].sum())
            if n == 0:
                continue
            low, up = wilson_interval(k, n, confidence)
            rows.append(BreakdownRow(name, float(edges[i]), float(high), n, k, k / n, low, up))
    return rows


def format_breakdown(rows: list[BreakdownRow], confidence: float = 0.95) -> str:
    """The rows as a small text table, one line per bin."""
    lines = [f"success by episode factor (equal-count bins, {round(100 * confidence)}% Wilson):"]
    width = max((len(r.factor) for r in rows), default=0)
    for i, r in enumerate(rows):
        name = r.factor if i == 0 or rows[i - 1].factor != r.factor else ""
        last_bin = i == len(rows) - 1 or rows[i + 1].factor != r.factor
        close = "]" if last_bin else ")"
        span = f"[{r.low:.4g}, {r.high:.4g}{close}"
        lines.append(
            f"  {name:<{width}}  {span:<22} {r.n:>7,}  {100 * r.rate:5.1f}% "
            f"[{100 * r.ci_low:.1f}, {100 * r.ci_high:.1f}]"
        )
    return "\n".join(lines)


__all__ = ["breakdown", "format_breakdown", "quantile_edges"]
