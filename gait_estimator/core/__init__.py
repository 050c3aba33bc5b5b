"""The algorithm, with no I/O beyond small option files: kernel libraries in memory, the
matcher (paper Algorithms 1 and 2), the estimator's stages (gaps, resampling, supervision,
walking calibration, personalisation), their options and the pipeline.

Imports only numpy, yaml (numba if installed) and itself.
"""
