"""openral_mjx: batched, vectorised evaluation of robot-manipulation policies on MuJoCo."""

__version__ = "0.1.0"
