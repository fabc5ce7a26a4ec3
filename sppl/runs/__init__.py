"""Running chains: one or many, in lockstep or in processes, checkpoints, locks, and data sets
of many scenes over executors."""
