"""Policy learning on the scenes: behaviour cloning of scripted experts, and PPO finetuning.

Sits between the entry points (`finetune.py`) and the runner: demonstrations and periodic
evaluations go through `rollout.EpisodeRunner`, the same code path as `python -m
openral_mjx.eval`; scenes know nothing of training.
"""
