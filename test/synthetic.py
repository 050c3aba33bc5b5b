"""Synthetic gait recordings with exact truth, generated from a kernel library.

Model: a sequence of strides, each in one mode. Stride k of mode m lasts
``N_m / rate * (1 + duration_cv * z_k)`` seconds (z ~ N(0, 1)); its angles at phase phi in [0, 1)
are

    mean_m + a(t) * (K_m(phi) - mean_m) + o(t) + blend(t) + noise

with K_m the kernel interpolated periodically in phase, mean_m its per-channel mean, a(t) and
o(t) per-channel amplitude factors (1 + amplitude_cv * z) and offsets (offset_sd_deg * z) drawn
per heel strike and interpolated linearly in time (so strides join continuously), blend(t) a
cosine fade over the first ``blend`` of a stride after a mode change that removes the jump from
the previous mode's end to the new mode's start, and white Gaussian sensor noise. A right foot
angle with one sharp maximum exactly at every right heel strike (phase 0) is added as
``extra['right_foot_deg']`` for heel-strike detection.

Sampling is uniform at ``rate_hz`` (stride durations are then whole numbers of samples, so every
heel strike is a sample) or jittered: intervals uniform in [(1 - jitter), (1 + jitter)] / rate
(``jitter``), or samples at the uniform grid times +- up to ``stamp_jitter_s`` (``stamp_jitter_s``),
with every heel strike inserted as a sample. Truth is exact: per-sample mode labels, heel-strike
flags and the phase (time since the heel strike / stride duration).

A *new wearer* (``new_wearer``) differs from the person the kernels came from the way a new user
or a re-donned sensor set does: one cadence factor c for the whole recording (every stride lasts
its duration / c), a constant per-channel sensor offset (``channel_offset_deg``), a per-channel
amplitude factor (``channel_gain``, multiplying a(t)), a sensor-noise level and a sampling rate
with jitter, each drawn uniformly from the ranges of ``WearerConfig``. The defaults of
``SyntheticConfig`` (c = 1, no offset, gain 1, no stamp jitter) leave ``generate`` as before:
the same seed gives the same recording.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from gait_estimator.core.kernels import KernelLibrary, KernelMode, make_mode, resample_stride
from gait_estimator.io.recording import Recording

FOOT_SHARPNESS = 10.0
"""Concentration of the foot-angle bump at heel strike (von Mises shape; larger = sharper)."""


@dataclass(frozen=True)
class SyntheticConfig:
    """Variability and sampling of a synthetic recording (degrees, seconds, Hz)."""

    duration_cv: float = 0.025
    amplitude_cv: float = 0.05
    offset_sd_deg: float = 0.5
    noise_sd_deg: float = 0.3
    rate_hz: float | None = None  # default: the library's rate
    jitter: float = 0.0  # 0 = uniform sampling
    blend: float = 0.25
    foot_amplitude_deg: float = 80.0
    foot_noise_sd_deg: float = 0.3
    cadence: float = 1.0  # stride-frequency factor of the wearer: every stride lasts (duration / cadence)
    channel_offset_deg: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)  # constant sensor offset per channel
    channel_gain: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)  # amplitude factor per channel (times a(t))
    stamp_jitter_s: float = 0.0  # samples at the uniform grid times +- up to this; 0 = off


@dataclass(frozen=True)
class WearerConfig:
    """Ranges (uniform) a new wearer is drawn from by ``new_wearer``.

    Attributes:
        offset_deg: Per-channel sensor offset in [-offset_deg, +offset_deg], degrees.
        amplitude: Per-channel amplitude factor in [1 - amplitude, 1 + amplitude].
        cadence: One stride-frequency factor in [1 - cadence, 1 + cadence] for every stride.
        noise_sd_deg: White sensor-noise standard deviation range, degrees.
        rate_hz: Sampling-rate range, Hz.
        jitter: Interval-jitter range (fraction of the nominal interval, see ``SyntheticConfig``).
    """

    offset_deg: float = 8.0
    amplitude: float = 0.15
    cadence: float = 0.12
    noise_sd_deg: tuple[float, float] = (0.2, 1.0)
    rate_hz: tuple[float, float] = (100.0, 500.0)
    jitter: tuple[float, float] = (0.0, 0.5)


WEARER_STREAM = 0x5EA2E2
"""First word of the seed of ``new_wearer``'s random stream (separate from ``generate``'s)."""


def near_copies(library: KernelLibrary, copies: int) -> KernelLibrary:
    """Every mode of ``library`` as ``copies`` kernels a fraction of a degree and of a percent apart,
    as a library with one kernel per ramp angle or walking speed step would hold them: copy v of
    N samples is stretched to N * (1 + 0.005 f) samples, its amplitude scaled by 1 + 0.01 f and
    its channels shifted by (0.25, -0.25, 0.1, 0) * f degrees, f = v - (copies - 1) / 2. Named
    MODE_0, MODE_1, ... (the mode is the part before the last underscore)."""
    modes = []
    for m in library.modes:
        for v in range(copies):
            f = v - (copies - 1) / 2
            k = m.samples * (1 + 0.01 * f) + np.array([0.25, -0.25, 0.1, 0.0]) * f
            modes.append(make_mode(f"{m.name}_{v}", resample_stride(k, round(m.length * (1 + 0.005 * f))),
                                   m.sample_rate_hz))
    return KernelLibrary(f"{library.name}_near_copies", tuple(modes))


def new_wearer(seed: int, ranges: WearerConfig | None = None, base: SyntheticConfig | None = None) -> SyntheticConfig:
    """A new wearer: ``base`` (default ``SyntheticConfig()``) with cadence, per-channel offsets
    and amplitude factors, noise level, sampling rate and jitter drawn from ``ranges``.

    The same seed gives the same wearer; pass the config to ``generate`` (any seed) to walk.
    """
    r = ranges or WearerConfig()
    rng = np.random.default_rng([WEARER_STREAM, seed])
    return replace(
        base or SyntheticConfig(),
        cadence=float(rng.uniform(1.0 - r.cadence, 1.0 + r.cadence)),
        channel_offset_deg=tuple(float(v) for v in rng.uniform(-r.offset_deg, r.offset_deg, 4)),
        channel_gain=tuple(float(v) for v in rng.uniform(1.0 - r.amplitude, 1.0 + r.amplitude, 4)),
        noise_sd_deg=float(rng.uniform(*r.noise_sd_deg)),
        rate_hz=float(rng.uniform(*r.rate_hz)),
        jitter=float(rng.uniform(*r.jitter)),
    )


@dataclass(frozen=True)
class Synthetic:
    """A generated recording and its exact truth.

    Attributes:
        recording: Angles (T, 4) deg, ``labels``, ``heel_strike`` flags, ``extra['right_foot_deg']``.
        heel_strikes_s: Exact right heel-strike times (S + 1,), s; the last one ends the last stride.
        phase: Exact phase [0, 1) of every sample, (T,).
        stride_modes: Mode of each stride, (S,).
        stride_durations_s: Duration of each stride, (S,), s.
    """

    recording: Recording
    heel_strikes_s: np.ndarray
    phase: np.ndarray
    stride_modes: list[str]
    stride_durations_s: np.ndarray


def _kernel_at(mode: KernelMode, phi: np.ndarray) -> np.ndarray:
    """Kernel angles (len(phi), 4) at phases ``phi`` (periodic linear interpolation)."""
    k = mode.samples
    n = k.shape[0]
    x = np.mod(phi, 1.0) * n
    i0 = np.floor(x).astype(np.int64) % n
    f = (x - np.floor(x))[:, None]
    return (1.0 - f) * k[i0] + f * k[(i0 + 1) % n]


def generate(
    library: KernelLibrary,
    segments: Sequence[tuple[str, int]],
    config: SyntheticConfig | None = None,
    seed: int = 0,
    duration_scale: Mapping[int, float] | None = None,
    source: str = "synthetic",
) -> Synthetic:
    """Generate a recording walking ``segments`` = [(mode name, number of strides), ...].

    Args:
        library: Kernels to walk with (names as in ``segments``).
        segments: Modes and stride counts in order.
        config: Variability and sampling.
        seed: Random seed (same seed, same recording).
        duration_scale: Optional extra factor on the duration of given stride numbers (0-based,
            counted over the whole recording), e.g. to plant an outlier.
        source: ``Recording.source`` text.
    """
    cfg = config or SyntheticConfig()
    rng = np.random.default_rng(seed)
    rate = float(cfg.rate_hz or library.sample_rate_hz)
    if cfg.jitter and cfg.stamp_jitter_s:
        raise ValueError("choose one of jitter and stamp_jitter_s")
    if not 0.0 <= cfg.stamp_jitter_s < 0.5 / rate:
        raise ValueError(f"stamp_jitter_s must be in [0, half the interval {0.5 / rate:g} s), got {cfg.stamp_jitter_s!r}")
    if not cfg.cadence > 0:
        raise ValueError(f"cadence must be > 0, got {cfg.cadence!r}")
    uniform = cfg.jitter == 0 and cfg.stamp_jitter_s == 0
    modes = [library.mode(name) for name, count in segments for _ in range(count)]
    s = len(modes)
    if s == 0:
        raise ValueError("no strides requested")
    nominal = np.array([m.length / library.sample_rate_hz for m in modes]) / cfg.cadence
    dur = nominal * np.maximum(0.5, 1.0 + cfg.duration_cv * rng.standard_normal(s))
    for k, f in (duration_scale or {}).items():
        dur[k] *= f
    if uniform:
        n_samples = np.maximum(2, np.round(dur * rate)).astype(np.int64)
        hs_index = np.r_[0, np.cumsum(n_samples)]
        dur = n_samples / rate
        hs = hs_index / rate
    else:
        hs = np.r_[0.0, np.cumsum(dur)]
    amp = np.asarray(cfg.channel_gain, dtype=np.float64) * (1.0 + cfg.amplitude_cv * rng.standard_normal((s + 1, 4)))
    off = cfg.offset_sd_deg * rng.standard_normal((s + 1, 4))

    if uniform:
        t = np.arange(hs_index[-1] + 1) / rate
        heel = np.isin(np.arange(t.size), hs_index)
    else:
        if cfg.jitter:
            lo, hi = (1.0 - cfg.jitter) / rate, (1.0 + cfg.jitter) / rate
            steps = rng.uniform(lo, hi, int(hs[-1] * rate / (1.0 - cfg.jitter)) + 10)
            t = np.cumsum(np.r_[0.0, steps])
        else:
            t = np.arange(math.floor(hs[-1] * rate) + 1) / rate
            t = t + rng.uniform(-cfg.stamp_jitter_s, cfg.stamp_jitter_s, t.size)
        t = t[(t > 0) & (t < hs[-1])]
        near_hs = np.abs(t[:, None] - hs[None, :]).min(axis=1) < 0.25 / rate
        t = np.union1d(t[~near_hs], hs)
        heel = np.isin(t, hs)

    k = np.clip(np.searchsorted(hs, t, side="right") - 1, 0, s - 1)
    frac = (t - hs[k]) / dur[k]  # in [0, 1]; 1 only for the final heel strike
    angles = np.empty((t.size, 4))
    for m in library.modes:
        rows = np.flatnonzero(np.array([modes[j].name == m.name for j in range(s)])[k])
        if rows.size == 0:
            continue
        mean = m.samples.mean(axis=0)
        a = (1 - frac[rows, None]) * amp[k[rows]] + frac[rows, None] * amp[k[rows] + 1]
        o = (1 - frac[rows, None]) * off[k[rows]] + frac[rows, None] * off[k[rows] + 1]
        angles[rows] = mean + a * (_kernel_at(m, frac[rows]) - mean) + o
    for j in range(1, s):
        if modes[j].name == modes[j - 1].name:
            continue
        prev, new = modes[j - 1], modes[j]
        pm, nm = prev.samples.mean(axis=0), new.samples.mean(axis=0)
        end_prev = pm + amp[j] * (_kernel_at(prev, np.array([1.0]))[0] - pm)
        start_new = nm + amp[j] * (_kernel_at(new, np.array([0.0]))[0] - nm)
        rows = np.flatnonzero((k == j) & (frac < cfg.blend))
        w = 0.5 * (1.0 + np.cos(np.pi * frac[rows] / cfg.blend))
        angles[rows] += w[:, None] * (end_prev - start_new)
    angles += cfg.noise_sd_deg * rng.standard_normal(angles.shape)
    angles += np.asarray(cfg.channel_offset_deg, dtype=np.float64)

    foot = cfg.foot_amplitude_deg * (np.exp(FOOT_SHARPNESS * (np.cos(2 * np.pi * frac) - 1.0)) - 0.6)
    foot += cfg.foot_noise_sd_deg * rng.standard_normal(t.size)
    labels = np.array([modes[j].name for j in k], dtype=object)
    rec = Recording(
        time_s=t, angles_deg=angles, labels=labels, heel_strike=heel, extra={"right_foot_deg": foot}, source=source
    )
    return Synthetic(rec, hs, np.mod(frac, 1.0), [m.name for m in modes], dur)


def with_stops(
    rec: Recording, stops: Mapping[int, float], stand_deg: np.ndarray, seed: int = 0, fade_s: float = 0.6,
    sway_deg: float = 0.5, sway_hz: float = 0.3,
) -> Recording:
    """``rec`` (a ``generate`` recording) with a stop of ``stops[k]`` seconds at its heel strike k:
    a cosine fade over ``fade_s`` from the pose at the heel strike to the standing pose
    ``stand_deg`` (C,), standing with a sinusoidal sway and the recording's noise level (estimated
    from its first 200 samples' sample-to-sample changes), a fade back,
    then the walk goes on from that heel strike (repeated). Stop rows are unlabelled and carry no
    heel strike (the right foot angle is held 40 deg below its heel-strike value); later rows are
    shifted in time."""
    rng = np.random.default_rng(seed)
    dt = float(np.median(np.diff(rec.time_s)))
    noise = float(np.std(np.diff(rec.angles_deg[:200], axis=0)) / math.sqrt(2))
    hs_rows = np.flatnonzero(rec.heel_strike)
    foot = rec.extra["right_foot_deg"]
    cols = {"t": rec.time_s, "a": rec.angles_deg, "l": rec.labels, "h": rec.heel_strike, "f": foot}
    out: dict[str, list[np.ndarray]] = {key: [] for key in cols}
    start, shift = 0, 0.0
    for k in sorted(stops):
        i = int(hs_rows[k])
        for key, v in cols.items():
            out[key].append(v[start:i + 1] + shift if key == "t" else v[start:i + 1])
        n = round(stops[k] / dt)
        u = np.arange(1, n + 1) * dt
        w = 0.5 * (1.0 - np.cos(np.pi * np.clip(np.minimum(u, stops[k] - u) / fade_s, 0.0, 1.0)))[:, None]
        sway = sway_deg * np.sin(2 * np.pi * sway_hz * u)[:, None]
        out["t"].append(rec.time_s[i] + shift + u)
        out["a"].append((1.0 - w) * rec.angles_deg[i] + w * (stand_deg + sway) + noise * rng.standard_normal((n, 4)))
        out["l"].append(np.full(n, "", dtype=object))
        out["h"].append(np.zeros(n, dtype=bool))
        out["f"].append(np.full(n, foot[i] - 40.0))
        shift += stops[k] + dt
        start = i
    for key, v in cols.items():
        out[key].append(v[start:] + shift if key == "t" else v[start:])
    joined = {key: np.concatenate(v) for key, v in out.items()}
    return Recording(time_s=joined["t"], angles_deg=joined["a"], labels=joined["l"], heel_strike=joined["h"],
                     extra={"right_foot_deg": joined["f"]}, source=f"{rec.source} with stops")
