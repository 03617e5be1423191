"""The evaluation library behind `python -m openral_mjx.eval`: build a scene, roll out seeds
with the runner, aggregate the report (`run`) under one checked `RunSpec` (`spec`); suites of
tasks (`suite`); re-simulating chosen episodes step by step (`replay`) and saving their sensor
frames (`frames`); a run stopped by a signal raises `Interrupted` with the report of what
finished, which its `resume` argument picks up (`partial`)."""

from openral_mjx.evaluation.partial import Interrupted
from openral_mjx.evaluation.provenance import device_description, package_versions
from openral_mjx.evaluation.run import Evaluation, build_scene, evaluate, run_evaluation
from openral_mjx.evaluation.sequential import SequentialRule
from openral_mjx.evaluation.spec import RunSpec

__all__ = [
    "Evaluation",
    "Interrupted",
    "RunSpec",
    "SequentialRule",
    "build_scene",
    "device_description",
    "evaluate",
    "package_versions",
    "run_evaluation",
]
