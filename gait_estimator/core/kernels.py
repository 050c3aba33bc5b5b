"""Kernel libraries: the average stride of every locomotion mode.

A kernel is one mode's average stride, N_m samples x 4 channels (CHANNELS order), in degrees,
starting at right heel strike. A library holds M kernels plus where they came from.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .channels import CHANNELS, N_CHANNELS
from .errors import LibraryError

REFERENCE_MODE_IDS = {"Slow": 1, "Med": 2, "Fast": 3, "RA": 4, "RD": 5, "SA": 6, "SD": 7}
"""Mode IDs of the paper's seven modes, as in the reference CSVs and output."""


STAND = "stand"
UNKNOWN = "unknown"
RESERVED_MODE_NAMES = (STAND, UNKNOWN)
"""What ``mode`` reads when the wearer is still or no kernel fits (``core/states.py``): no library
mode may take these names."""


def reserved_name(name: str) -> str:
    """Why ``name`` cannot name a mode (one of ``RESERVED_MODE_NAMES``)."""
    return f"mode name {name!r} is reserved: the estimator reports it when no library mode applies"


@dataclass(frozen=True)
class KernelMode:
    """One locomotion mode's kernel.

    Attributes:
        name: Mode name, unique within its library (e.g. ``"Slow"``).
        samples: Float64 array (N_m, 4), degrees, channels in CHANNELS order; row 0 is right
            heel strike and the rows cover exactly one stride.
        sample_rate_hz: Rate (Hz) at which the rows are spaced; stride duration = N_m / rate.
        mode_id: Optional numeric ID (the reference data's ``ID``; 0 when none).
        info: Free-form metadata (e.g. training statistics: stride count, duration mean/std).
    """

    name: str
    samples: np.ndarray
    sample_rate_hz: float
    mode_id: int = 0
    info: Mapping[str, Any] = field(default_factory=dict)

    @property
    def length(self) -> int:
        """N_m, the number of samples in one stride."""
        return int(self.samples.shape[0])

    @property
    def stride_duration_s(self) -> float:
        """Stride duration in seconds implied by N_m and the sample rate."""
        return self.length / self.sample_rate_hz


@dataclass(frozen=True)
class KernelLibrary:
    """An ordered set of kernels with provenance.

    Attributes:
        name: Library name (e.g. ``"able_bodied"``).
        modes: The kernels, in matching order (ties go to the earlier mode).
        provenance: Where the kernels come from: ``source``, ``license``, ``built_by`` ...
        path: File the library was read from, if any (for messages only).
    """

    name: str
    modes: tuple[KernelMode, ...]
    provenance: Mapping[str, Any] = field(default_factory=dict)
    path: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "modes", tuple(self.modes))
        validate_library(self)

    def __len__(self) -> int:
        return len(self.modes)

    def __iter__(self) -> Iterator[KernelMode]:
        return iter(self.modes)

    @property
    def mode_names(self) -> list[str]:
        return [m.name for m in self.modes]

    @property
    def lengths(self) -> np.ndarray:
        """N_m for every mode, int64 array (M,)."""
        return np.array([m.length for m in self.modes], dtype=np.int64)

    @property
    def sample_rate_hz(self) -> float:
        """The library's sample rate; all modes of one library share it."""
        return self.modes[0].sample_rate_hz

    def mode(self, name: str) -> KernelMode:
        for m in self.modes:
            if m.name == name:
                return m
        raise KeyError(f"no mode {name!r} in library {self.name!r} (modes: {', '.join(self.mode_names)})")

    def replicated(self, count: int) -> KernelLibrary:
        """A library of ``count`` modes made by cycling through this one's (for benchmarks).

        Copies after the first round get a tiny deterministic offset so they are not exact ties.
        """
        modes = []
        for i in range(count):
            base = self.modes[i % len(self.modes)]
            rnd = i // len(self.modes)
            modes.append(
                KernelMode(
                    name=base.name if rnd == 0 else f"{base.name}_{rnd}",
                    samples=base.samples + 1e-3 * rnd,
                    sample_rate_hz=base.sample_rate_hz,
                    mode_id=base.mode_id,
                )
            )
        return KernelLibrary(f"{self.name}_x{count}", tuple(modes), dict(self.provenance))


def validate_library(lib: KernelLibrary) -> None:
    """Raise LibraryError (naming the file and the problem) unless ``lib`` is well formed."""
    where = lib.path or f"library {lib.name!r}"
    if not lib.name:
        raise LibraryError(f"{where}: missing library name")
    if not lib.modes:
        raise LibraryError(f"{where}: library has no modes")
    seen: set[str] = set()
    rate = lib.modes[0].sample_rate_hz
    for m in lib.modes:
        if not isinstance(m.name, str) or not m.name:
            raise LibraryError(f"{where}: a mode has no name")
        if m.name in RESERVED_MODE_NAMES:
            raise LibraryError(f"{where}: {reserved_name(m.name)}")
        if m.name in seen:
            raise LibraryError(f"{where}: duplicate mode name {m.name!r}")
        seen.add(m.name)
        s = m.samples
        if not isinstance(s, np.ndarray) or s.ndim != 2 or s.shape[1] != N_CHANNELS:
            shape = getattr(s, "shape", None)
            raise LibraryError(
                f"{where}: mode {m.name!r} has shape {shape}, expected (N, {N_CHANNELS}) "
                f"for channels {', '.join(CHANNELS)}"
            )
        if s.dtype != np.float64:
            raise LibraryError(f"{where}: mode {m.name!r} samples must be float64, got {s.dtype}")
        if s.shape[0] < 2:
            raise LibraryError(f"{where}: mode {m.name!r} has N={s.shape[0]} samples, need at least 2")
        if not np.all(np.isfinite(s)):
            bad = int(np.argwhere(~np.isfinite(s))[0][0])
            raise LibraryError(f"{where}: mode {m.name!r} has a non-finite value at sample {bad}")
        r = m.sample_rate_hz
        if not (isinstance(r, (int, float)) and np.isfinite(r) and r > 0):
            raise LibraryError(f"{where}: mode {m.name!r} has invalid sample_rate_hz {r!r}")
        if abs(r - rate) > 1e-9 * rate:
            raise LibraryError(
                f"{where}: mode {m.name!r} sample_rate_hz {r} differs from {rate} "
                "(all modes of a library share one rate)"
            )


def make_mode(
    name: str,
    samples: Any,
    sample_rate_hz: float,
    mode_id: int = 0,
    info: Mapping[str, Any] | None = None,
) -> KernelMode:
    """Build a KernelMode, converting ``samples`` to a read-only float64 (N, 4) array."""
    arr = np.array(samples, dtype=np.float64)
    arr.setflags(write=False)
    return KernelMode(str(name), arr, float(sample_rate_hz), int(mode_id), dict(info or {}))


def near_duplicates(
    library: KernelLibrary,
    max_rms_deg: float,
    max_length_ratio: float,
    channel_weights: np.ndarray | None = None,
) -> np.ndarray:
    """Which modes' kernels are near copies of each other: (M, M) bool, True on the diagonal.

    Modes a and b are near copies when their stride lengths differ by at most
    ``max_length_ratio`` (|ln(N_a / N_b)| <=) and their shapes, both resampled to the library's
    longest stride, differ by at most ``max_rms_deg`` (RMS over samples and channels, degrees,
    channels weighted by ``channel_weights``, at the best circular shift). A matcher tells such
    modes apart only by noise: a library can hold them (e.g. one kernel per ramp angle).
    """
    m = len(library)
    lengths = library.lengths
    big = int(lengths.max())
    w = np.ones(N_CHANNELS) if channel_weights is None else np.asarray(channel_weights, dtype=np.float64)
    w = w / w.sum()
    x = np.stack([resample_stride(k.samples, big) for k in library.modes]) * np.sqrt(w)  # (M, L, C)
    f = np.fft.rfft(x, axis=1)
    energy = np.einsum("mlc,mlc->m", x, x)
    log_len = np.log(lengths)
    order = np.argsort(log_len, kind="stable")  # chunks of similar lengths: few candidates each
    sorted_len = log_len[order]
    near = np.eye(m, dtype=bool)
    chunk = max(1, 4096 // m)
    for a0 in range(0, m, chunk):
        a = order[a0:a0 + chunk]
        lo = np.searchsorted(sorted_len, log_len[a].min() - max_length_ratio, side="left")
        hi = np.searchsorted(sorted_len, log_len[a].max() + max_length_ratio, side="right")
        b = order[lo:hi]
        cross = np.fft.irfft(np.einsum("afc,bfc->abf", f[a], f[b].conj()), n=big, axis=2)  # (A, B, L) over shifts
        msd = (energy[a, None] + energy[None, b] - 2.0 * cross.max(axis=2)) / big
        close = np.sqrt(np.maximum(msd, 0.0)) <= max_rms_deg
        near[a[:, None], b[None, :]] |= close & (np.abs(log_len[a, None] - log_len[None, b]) <= max_length_ratio)
    return near


def resample_stride(samples: np.ndarray, n: int) -> np.ndarray:
    """One stride (N, C) resampled to ``n`` samples by periodic linear interpolation.

    Row 0 stays at phase 0 and row k of the result is the stride at phase k / n, so a stride
    stretched by s is ``resample_stride(samples, round(s * N))``; ``n == N`` returns a copy.
    """
    x = np.asarray(samples, dtype=np.float64)
    length = x.shape[0]
    if n == length:
        return x.copy()
    pos = np.arange(n) * (length / n)
    i0 = np.floor(pos).astype(np.int64)
    f = (pos - i0)[:, None]
    return (1.0 - f) * x[i0 % length] + f * x[(i0 + 1) % length]
