"""Online personalisation: confident strides pull their mode's kernel towards the wearer.

At every right heel strike of the reported mode (its phase wraps from the end of a stride to the
start of the next), the stride that just ended (the samples since the previous heel strike of the
same mode, on the library's clock) is time-normalised to the kernel's N_m samples and, if it
passes every guard, averaged into the kernel:

    k <- k + rate * clip(stride - k, -max_step_deg, +max_step_deg)

so one stride moves no kernel sample by more than ``rate * max_step_deg`` degrees, however bad it
is. Before averaging, the stride is shifted by the few samples that best align it with the kernel
(``aligned``), so that the kernel's phase origin (0 = heel strike) stays put. Guards (a stride
failing one is skipped, counted by reason):

* ``held``: the reported mode was held (low confidence, dwell, transitions) at some sample of the
  stride, or it changed during the stride;
* ``confidence``: the confidence margin fell below ``min_confidence`` during the stride;
* ``duration``: the stride (time between two heel strikes of the mode) differs from the length
  of the kernel variant the matcher chose by more than ``duration_tolerance`` (10 %: the duration
  floor of ``train``'s outlier rule);
* ``shape``: its RMS distance from the kernel exceeds the median distance of the mode's recent
  candidate strides by more than max(``shape_sigmas`` robust sigmas, the median) (``train``'s
  shape rule, applied to a sliding history of ``history`` strides); the first ``warmup``
  candidates of a mode only fill that history;
* ``unchecked``: the stride ended while the personalisation was paused (``Personaliser.paused``:
  input angles not known to be right yet, such as an IMU calibration not yet checked).

``Personaliser`` is the pipeline stage: it keeps the last stride's samples and hands every ended
stride to ``KernelAdapter``, then the adapted kernel to the matcher.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from .channels import N_CHANNELS, Sample
from .kernels import KernelLibrary, make_mode, resample_stride
from .matcher import IncrementalMatcher, StepResult
from .options import EstimatorConfig
from .supervisor import Estimate

MAD_TO_SIGMA = 1.4826  # median absolute deviation -> standard deviation of a normal distribution
SKIP_REASONS = ("held", "confidence", "duration", "warmup", "shape", "unchecked")  # keys of KernelAdapter.skipped


def robust_sigma(x: np.ndarray) -> float:
    """1.4826 x median absolute deviation of ``x`` (a robust standard deviation; ``train``'s
    outlier rules and the personalisation's shape guard)."""
    x = np.asarray(x, dtype=np.float64)
    return float(MAD_TO_SIGMA * np.median(np.abs(x - np.median(x)))) if x.size else math.nan


@dataclass(frozen=True)
class AdaptParams:
    """Personalisation settings.

    Attributes:
        rate: Weight of one accepted stride in the kernel update, (0, 1]; 0 = off.
        min_confidence: Lowest confidence margin allowed during an adapted stride.
        max_step_deg: Per-sample clip of (stride - kernel) before weighting, degrees.
        duration_tolerance: Largest relative difference between a stride's duration and the
            chosen kernel variant's length.
        shape_sigmas: Robust sigmas beyond the median distance that make a stride an outlier.
        history: Candidate strides per mode kept for the shape rule.
        warmup: Candidates of a mode that only fill the history.
        max_shift: Largest alignment shift, fraction of the stride either way.
    """

    rate: float = EstimatorConfig.adapt_rate
    min_confidence: float = EstimatorConfig.adapt_min_confidence
    max_step_deg: float = EstimatorConfig.adapt_max_step_deg
    duration_tolerance: float = 0.10
    shape_sigmas: float = 3.5
    history: int = 16
    warmup: int = 3
    max_shift: float = 0.05


def aligned(stride: np.ndarray, kernel: np.ndarray, max_shift: float = 0.05) -> np.ndarray:
    """``stride`` (N, 4) circularly shifted by the whole number of samples (at most
    ``max_shift`` x N either way) that brings it closest (least squares) to ``kernel`` (N, 4).

    The heel strikes that cut a stride out of the stream come from the estimated phase, which
    may be a sample or two off; averaging unaligned strides would move the kernel's phase origin
    a little with every update, and the updates would then follow it.
    """
    n = kernel.shape[0]
    # sum_c sum_t stride[t - s] kernel[t]: circular cross-correlation, for every shift s
    corr = np.fft.irfft((np.fft.rfft(kernel, axis=0) * np.conj(np.fft.rfft(stride, axis=0))).sum(axis=1), n=n)
    limit = int(max_shift * n)
    shifts = np.r_[0 : limit + 1, n - limit : n] if limit > 0 else np.zeros(1, dtype=np.int64)
    best = int(shifts[np.argmax(corr[shifts])])
    return np.roll(stride, best, axis=0)


class KernelAdapter:
    """Tracks strides of the reported mode and updates kernels (see the module docstring).

    Args:
        library: The library being adapted (its kernels are the starting point).
        options: Rate and guards.
    """

    def __init__(self, library: KernelLibrary, options: AdaptParams) -> None:
        self.library = library
        self.options = options
        self.kernels = [m.samples.copy() for m in library.modes]
        self.accepted = np.zeros(len(library), dtype=np.int64)
        self.skipped: Counter = Counter()
        self._dist: list[deque] = [deque(maxlen=options.history) for _ in library.modes]
        self.reset()

    def adopt(self, other: KernelAdapter) -> None:
        """Continue from ``other``'s kernels, stride counts and outlier history (same library)."""
        self.kernels = [k.copy() for k in other.kernels]
        self.accepted = other.accepted.copy()
        self.skipped = other.skipped.copy()
        self._dist = [deque(d, maxlen=d.maxlen) for d in other._dist]

    def reset(self) -> None:
        """Forget the stride in progress (after a window restart); kernels stay adapted."""
        self._mode: int | None = None
        self._start: int | None = None
        self._last_phase = math.nan
        self._clean = False
        self._min_conf = math.inf

    @property
    def stride_start(self) -> int | None:
        """Sample number (in the estimator's count) of the heel strike that began the stride in
        progress, if it is one being tracked."""
        return self._start

    def ends_stride(self, mode: int, phase: float) -> bool:
        """True if an estimate of ``mode`` at ``phase`` is a heel strike that ends a tracked
        stride of that mode (its phase wrapped); then call ``finish_stride`` before ``track``."""
        return self._mode == mode and self._start is not None and phase < self._last_phase - 0.5

    def finish_stride(self, mode: int, samples: np.ndarray, expected_samples: float) -> np.ndarray | None:
        """The stride of ``mode`` that just ended: ``samples`` (D, 4) degrees, from the heel strike
        that began it to the sample before the one that ends it; ``expected_samples`` = the
        length of the kernel variant the matcher chose. Returns the updated kernel (N_m, 4) if
        the stride passed every guard, else None (the reason is counted)."""
        k = self.kernels[mode]
        if not self._clean:
            return self.skip_stride("held")
        if self._min_conf < self.options.min_confidence:
            return self.skip_stride("confidence")
        if abs(samples.shape[0] / expected_samples - 1.0) > self.options.duration_tolerance:
            return self.skip_stride("duration")
        obs = aligned(resample_stride(samples, k.shape[0]), k, self.options.max_shift)
        dist = float(np.sqrt(np.mean((obs - k) ** 2)))
        history = self._dist[mode]
        history.append(dist)
        if len(history) <= self.options.warmup:
            return self.skip_stride("warmup")
        h = np.asarray(history)
        med = float(np.median(h))
        sigma = robust_sigma(h)
        if dist > med + max(self.options.shape_sigmas * sigma, med):
            return self.skip_stride("shape")
        step = np.clip(obs - k, -self.options.max_step_deg, self.options.max_step_deg)
        self.kernels[mode] = k + self.options.rate * step
        self.accepted[mode] += 1
        return self.kernels[mode]

    def track(self, step: int, mode: int, phase: float, held: bool, confidence: float, ready: bool) -> None:
        """Account for the estimate of sample number ``step`` (reported mode, its phase, held
        flag, confidence)."""
        if not ready:
            self.reset()
            return
        if self._mode == mode and phase < self._last_phase - 0.5:  # heel strike: a stride starts
            self._start, self._clean, self._min_conf = step, True, math.inf
        elif self._mode != mode:
            self._start, self._clean, self._min_conf = None, False, math.inf
        self._mode = mode
        self._last_phase = phase
        self._clean = self._clean and not held
        self._min_conf = min(self._min_conf, confidence)

    def skip_stride(self, reason: str) -> None:
        """Count a stride that ended without being adopted, for ``reason`` (SKIP_REASONS)."""
        assert reason in SKIP_REASONS, reason
        self.skipped[reason] += 1
        return None

    def adapted_library(self) -> KernelLibrary:
        """The library with the adapted kernels; provenance says how many strides each took."""
        modes = []
        for m, k, n in zip(self.library.modes, self.kernels, self.accepted, strict=True):
            modes.append(make_mode(m.name, k, m.sample_rate_hz, m.mode_id, {**m.info, "adapted_strides": int(n)}))
        prov = dict(self.library.provenance)
        prov["adapted_from"] = self.library.path or self.library.name
        prov["adaptation"] = {
            "rate": self.options.rate,
            "min_confidence": self.options.min_confidence,
            "max_step_deg": self.options.max_step_deg,
            "accepted_strides": {m.name: int(n) for m, n in zip(self.library.modes, self.accepted, strict=True)},
            "skipped_strides": dict(self.skipped),
        }
        return KernelLibrary(self.library.name, tuple(modes), prov)


class Personaliser:
    """The personalisation stage of the estimator: keeps the samples of the stride in progress
    (on the library's clock) and, where a tracked stride of the reported mode ends, lets the
    adapter update that mode's kernel in the matcher.

    Args:
        library: The library being adapted.
        params: Rate and guards.
        matcher: The matcher whose kernels follow the adapted ones.
    """

    def __init__(self, library: KernelLibrary, params: AdaptParams, matcher: IncrementalMatcher) -> None:
        self.adapter = KernelAdapter(library, params)
        self.matcher = matcher
        self.paused = False
        """True: strides that end are counted as skipped ('unchecked') and no kernel changes
        (the input's angles are not known to be right yet)."""
        self._history = np.zeros((2 * matcher.max_length, N_CHANNELS))  # the last stride, however long

    def observe(self, x: Sample, est: Estimate, result: StepResult) -> None:
        """Account for the matcher sample ``x`` and its estimate."""
        adapter, matcher = self.adapter, self.matcher
        step = matcher.steps - 1  # this sample's number since the window (re)started
        h = self._history.shape[0]
        self._history[step % h] = x
        m = est.mode_index
        start = adapter.stride_start
        if est.ready and start is not None and adapter.ends_stride(m, est.phase) and step - start <= h:
            if self.paused:
                adapter.skip_stride("unchecked")
            else:
                stride = self._history[np.arange(start, step) % h]
                variant = 0 if result.variant is None else int(result.variant[m])
                new = adapter.finish_stride(m, stride, float(matcher.lengths[matcher.row_of(m, variant)]))
                if new is not None:
                    matcher.set_kernel(m, new)
        adapter.track(step, m, est.phase, est.held, est.confidence, est.ready)

    def adopt(self, other: Personaliser, same_library: bool) -> None:
        """Continue from the kernels ``other`` has personalised (``same_library``: its modes
        are this one's)."""
        if not same_library or not other.adapter.accepted.sum():
            return
        self.adapter.adopt(other.adapter)
        for m in np.flatnonzero(self.adapter.accepted):  # once per option change, not per sample
            self.matcher.set_kernel(int(m), self.adapter.kernels[m])
