"""After the runs: comparisons of logs and plants, reports and tables, sweeps on Dask, summary metrics."""
