"""Offline tools: heel strikes and strides, labels, training kernels, evaluating accuracy,
figures, matcher benchmarks.

Imports ``core`` and ``io``; never ``ros`` or ``cli``.
"""
