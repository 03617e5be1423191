"""openral_mjx: batched, vectorised evaluation of robot-manipulation policies on MuJoCo."""

from openral_mjx.core.cpu_codegen import pin_cpu_isa

# Before anything starts JAX's CPU backend: a seed's bits must not depend on its batch lane.
pin_cpu_isa()

__version__ = "0.1.0"
