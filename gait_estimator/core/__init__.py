"""The algorithm, with no I/O beyond small option files: kernel libraries in memory, the
matcher (paper Algorithms 1 and 2), resampling, supervision and the estimator pipeline.

Imports only numpy/scipy/yaml and itself.
"""
