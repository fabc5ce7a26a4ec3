"""The trace-based sampler: the chain, its jumps and parameter moves, and their proposals."""
