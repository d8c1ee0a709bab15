"""The experiments: scenarios, runs with every node in one process, run logs and metrics,
figures, randomized runs, and the worker processes that run them in parallel."""
