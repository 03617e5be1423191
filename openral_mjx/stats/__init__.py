"""Success-rate statistics: binomial intervals (`intervals`), comparisons of two policies
(`comparison`, and `report_comparison` for two reports), paired differences of a continuous
per-episode value such as steps or reward (`continuous`), the exact group-sequential design
(`sequential`), sample sizes planned before a run (`planning`), families of comparisons (two
suites task by task, k policies pairwise: `families`, and `report_families` for reports) and the
success breakdown by episode factor (`breakdown`).

A new statistic goes in the module of its kind, with an exact or simulated oracle in
`tests/stats/`; what users call is re-exported here.
"""

from openral_mjx.stats.breakdown import breakdown, format_breakdown
from openral_mjx.stats.comparison import (
    UNPAIRED_TESTS,
    Comparison,
    holm_adjusted,
    mcnemar_exact_pvalue,
    newcombe_interval,
    newcombe_paired_interval,
    paired_comparison,
    two_proportion_z_pvalue,
    unpaired_comparison,
)
from openral_mjx.stats.continuous import PairedMean, paired_mean_difference, t_interval
from openral_mjx.stats.families import ManyComparison, SuiteComparison, compare_many, compare_suites
from openral_mjx.stats.intervals import (
    INTERVAL_METHODS,
    binomial_interval,
    check_confidence,
    clopper_pearson_interval,
    episodes_for_halfwidth,
    wilson_interval,
    z_value,
)
from openral_mjx.stats.planning import (
    PLAN_CAP,
    PairedDesign,
    PairedPlan,
    Pilot,
    format_interval_plan,
    format_paired_plan,
    mcnemar_critical_counts,
    mcnemar_power,
    plan_paired,
)
from openral_mjx.stats.report_comparison import (
    ReportComparison,
    check_comparable,
    compare_reports,
    format_comparison,
)
from openral_mjx.stats.report_families import compare_many_reports, compare_suite_reports
from openral_mjx.stats.sequential import SequentialDesign, sufficient_episodes

__all__ = [
    "INTERVAL_METHODS",
    "PLAN_CAP",
    "UNPAIRED_TESTS",
    "Comparison",
    "ManyComparison",
    "PairedDesign",
    "PairedMean",
    "PairedPlan",
    "Pilot",
    "ReportComparison",
    "SequentialDesign",
    "SuiteComparison",
    "binomial_interval",
    "breakdown",
    "check_comparable",
    "check_confidence",
    "clopper_pearson_interval",
    "compare_many",
    "compare_many_reports",
    "compare_reports",
    "compare_suite_reports",
    "compare_suites",
    "episodes_for_halfwidth",
    "format_breakdown",
    "format_comparison",
    "format_interval_plan",
    "format_paired_plan",
    "holm_adjusted",
    "mcnemar_critical_counts",
    "mcnemar_exact_pvalue",
    "mcnemar_power",
    "newcombe_interval",
    "newcombe_paired_interval",
    "paired_comparison",
    "paired_mean_difference",
    "plan_paired",
    "sufficient_episodes",
    "t_interval",
    "two_proportion_z_pvalue",
    "unpaired_comparison",
    "wilson_interval",
    "z_value",
]
