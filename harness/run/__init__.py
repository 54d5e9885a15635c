"""The runner: job identity and hashing, executors (local pool, Dask), storage of results,
the run lock."""
