"""Speed measured side by side in one run (what `python -m openral_mjx.bench` reports): the
evaluator against raw physics ceilings and MuJoCo C (`throughput`), ray-cast sensors against
raw `mjx.ray` and `mj_multiRay` (`rays`)."""
