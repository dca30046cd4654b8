"""What the dynamometer under the arm reads (`arm.base: dynamometer`, `assemble.rig`).

The run records the load the arm and the top plate put on the plate's sensors since the start
(`dynamometer_force_N`, `dynamometer_moment_Nm`, the plate's axes, about its top surface's
centre): its mechanical response is in that load. The charge amplifier's low-pass filter (a
Butterworth of `filter_order` at `filter_cutoff_Hz`, run forward in time as an analogue filter
is: it delays as well as smooths) acts on the recorded series, and the recorder keeps every
sample at `sampling_Hz`. The readings are then turned into the grasp frame O_a at the start, the
axes the contact force is given in, so the two compare axis by axis.

The recorded series stands in for the continuous load: its rate must be well above the
filter's cut-off (the scenario's checks ask for ten times), and an integer multiple of the
sampling rate.
"""

from __future__ import annotations

import numpy as np


def settings(s, R_A: np.ndarray) -> dict:
    """The instrument's settings as a run's summary keeps them (`reading` reads them):
    R_A (3, 3), the grasp frame's axes in the plate's (world) at the start."""
    dyn = s.dynamometer
    return {"filter_cutoff_Hz": dyn.filter_cutoff_Hz, "filter_order": dyn.filter_order,
            "sampling_Hz": dyn.sampling_Hz, "grasp_axes_in_plate": np.asarray(R_A).tolist()}


def reading(ts: dict, setting: dict) -> dict:
    """The dynamometer's samples from a run's series and its `settings`: {"t": (n,),
    "force_N": (n, 3), "moment_Nm": (n, 3)}, force and moment in O_a's axes at the start."""
    from scipy import signal

    t = np.asarray(ts["t"])
    rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 else 0.0
    every = max(1, int(round(rate / setting["sampling_Hz"]))) if rate else 1
    R = np.array(setting["grasp_axes_in_plate"])
    out = {"t": t[::every]}
    for name, key in (("force_N", "dynamometer_force_N"), ("moment_Nm", "dynamometer_moment_Nm")):
        x = np.asarray(ts[key])
        if rate > 2.0 * setting["filter_cutoff_Hz"]:
            sos = signal.butter(setting["filter_order"], setting["filter_cutoff_Hz"], fs=rate, output="sos")
            x = signal.sosfilt(sos, x, axis=0)
        out[name] = (x @ R)[::every]
    return out


def peaks(samples: dict) -> dict:
    """The largest |reading| per axis (O_a) over the samples."""
    return {"peak_force_N": np.abs(samples["force_N"]).max(axis=0).tolist(),
            "peak_moment_Nm": np.abs(samples["moment_Nm"]).max(axis=0).tolist()}


def after_grasp(samples: dict, t_complete: float) -> dict | None:
    """What the reading does after the grasp completed (`completion.record_after_s`), per axis
    of O_a: its mean over the window's second half (what the bungee and gravity leave on the
    plate), its largest swing about that mean, and the frequency of its largest spectral line
    (the ringing's). None without at least a second of samples after the completion."""
    t = samples["t"]
    after = t > t_complete
    if not after.any() or t[-1] - t_complete < 1.0:
        return None
    x, tt = samples["force_N"][after], t[after]
    late = tt >= tt[0] + 0.5 * (tt[-1] - tt[0])
    mean = x[late].mean(axis=0)
    swing = x - mean
    spectrum = np.abs(np.fft.rfft(swing - swing.mean(axis=0), axis=0))
    freqs = np.fft.rfftfreq(len(tt), (tt[-1] - tt[0]) / (len(tt) - 1))
    return {"window_s": float(tt[-1] - t_complete), "mean_force_N": mean.tolist(),
            "largest_swing_N": np.abs(swing).max(axis=0).tolist(),
            "ringing_Hz": [float(freqs[1:][np.argmax(spectrum[1:, a])]) for a in range(3)]}
