"""When each camera fires in a clip: 12 Hz sweeps with per-camera offsets, 2 Hz samples, key-frame choice."""

from dataclasses import dataclass

import numpy as np

from cama_pipeline.synthetic.rig import RigCamera


@dataclass(frozen=True)
class CameraShot:
    """One camera image of a clip."""

    channel: str
    timestamp_us: int
    sample_index: int
    """The sample (key frame) this image belongs to: its key frame if `is_key_frame`, else the nearest."""
    is_key_frame: bool
    sweep_index: int


@dataclass(frozen=True)
class ClipSchedule:
    """Sample timestamps and every camera shot of a clip, in time order per camera."""

    sample_times_us: tuple[int, ...]
    shots: tuple[CameraShot, ...]


def schedule_clip(
    start_time_us: int, duration_s: float, rig: tuple[RigCamera, ...], sweep_hz: float, sample_hz: float
) -> ClipSchedule:
    """Sweeps every 1/sweep_hz (plus each camera's offset), samples every 1/sample_hz."""
    n_samples = int(np.floor(duration_s * sample_hz)) + 1
    sample_times = [start_time_us + int(round(k * 1e6 / sample_hz)) for k in range(n_samples)]
    n_sweeps = int(np.floor(duration_s * sweep_hz)) + 1
    nominal = start_time_us + np.round(np.arange(n_sweeps) * 1e6 / sweep_hz).astype(np.int64)
    samples = np.asarray(sample_times)
    # A sample's key frames are one sweep of all cameras (the sweep nominally nearest to it), so the six
    # key-frame images of a sample fire within the rig's trigger spread, as nuScenes' do.
    key_sweeps = {int(np.argmin(np.abs(nominal - ts))): k for k, ts in enumerate(sample_times)}
    nearest_sample = np.abs(nominal[:, None] - samples[None, :]).argmin(axis=1)
    shots: list[CameraShot] = []
    for cam in rig:
        for j, ts in enumerate(nominal + cam.offset_us):
            shots.append(
                CameraShot(
                    cam.channel, int(ts), key_sweeps.get(j, int(nearest_sample[j])), j in key_sweeps, j
                )
            )
    return ClipSchedule(tuple(sample_times), tuple(shots))
