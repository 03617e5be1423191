"""What the commands (`eval`, `compare`, `bench`, `finetune`) share: one-line errors with exit
code 2, reproducible command lines, progress output."""
