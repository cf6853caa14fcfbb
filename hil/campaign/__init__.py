"""HIL campaigns: sweeps and Monte-Carlo draws of whole HIL runs on Dask (`hydrapod campaign`)."""
