import cdprctl  # noqa: F401  first: the kernels' cache chosen before any is compiled
