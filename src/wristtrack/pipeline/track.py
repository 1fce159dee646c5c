"""``wristtrack track``: a recording in, poses.csv and summary.json out, one frame at a time.

Frames stream from the reader through the detector and the tracker to the writer, so memory
stays flat however long the recording, and every processed frame is on disk as soon as it is
done: an interrupted run keeps what it computed. The first seconds are the exception: their
detections are held until they have primed the noise (pipeline/priming.py), then tracked and
written.
"""

from __future__ import annotations

import math
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from wristtrack.analysis.kinematics import analyse_file
from wristtrack.analysis.summary import SummaryAccumulator, camera_pose_dict
from wristtrack.detect.config import DetectorConfig, detector_config
from wristtrack.detect.detector import MarkerDetector
from wristtrack.errors import InitialisationError, InputError
from wristtrack.io.atomic import write_json_atomic
from wristtrack.io.base import Recording
from wristtrack.io.poses import PosesWriter
from wristtrack.io.prefetch import frames_ahead
from wristtrack.io.run_folder import SURVEYED_HAND
from wristtrack.io.states import STATES_FILE, StateWriter
from wristtrack.pipeline import checkpoint as ckpt
from wristtrack.pipeline.frame_step import Rows, RunState, came_without_depth, track_frame
from wristtrack.pipeline.interrupt import DeferredInterrupt
from wristtrack.pipeline.priming import Priming
from wristtrack.pipeline.refit import clear_refit, refit_begun, refit_run
from wristtrack.pipeline.sinks import NoStates, progress_bar
from wristtrack.pipeline.smoothing import smooth_run
from wristtrack.pipeline.surveyed import (
    hand_of,
    layout_origin,
    load_surveyed,
    second_pass_begun,
)
from wristtrack.tracking.layout_survey import RunSurvey
from wristtrack.tracking.models import reads_camera_timing
from wristtrack.tracking.smoother_noise import refits
from wristtrack.tracking.tracker import Tracker, TrackerConfig

if TYPE_CHECKING:
    from wristtrack.pipeline.label import ManualLabels


def track_recording(
    recording: Recording,
    out: str | Path,
    config: TrackerConfig | None = None,
    labels: np.ndarray | ManualLabels | None = None,
    progress: bool = True,
    smooth: bool = False,
    overlay: Any = None,
    resume: bool = False,
    checkpoint_every: int = ckpt.CHECKPOINT_FRAMES,
    detector: str = "default",
    survey: bool = True,
) -> dict[str, Any]:
    """Track every frame of ``recording``; write ``out``/poses.csv and ``out``/summary.json.

    ``labels`` (M,) optionally names the blobs of the first frame (manual labelling) when the
    automatic labelling cannot; a ``label.ManualLabels`` (labels.json) names those of its own
    frame, matched by pixel position (until then the automatic labelling may initialise).
    ``smooth`` replaces the filtered poses by the unscented RTS smoother's once the run is
    complete (the filtered ones stay in poses_filtered.csv); with ``config.smoothing_noise``
    "learned", a recording that can be read again is then tracked once more, and smoothed, at
    the angular process noise its smoothed rates show (:mod:`wristtrack.pipeline.refit`).
    ``overlay`` (an overlay.OverlayWriter) receives every frame with its detections and
    estimate. ``detector`` names the marker detector's preset: "default" (ours) or "paper"
    (the paper's as published, :mod:`wristtrack.detect.paper`). Returns the summary.

    Without hand.json (``recording.hand`` None) and with ``survey``, the run takes two passes:
    the first measures the subject's layout over the whole recording
    (:mod:`wristtrack.tracking.layout_survey`) and writes it to ``out``/hand_surveyed.json
    (hand.json's format, for the same subject's other recordings); the second tracks with it.
    A live camera cannot be read twice and is tracked once.

    Interrupted runs: Ctrl-C or SIGTERM stops at the end of the frame being processed (in the
    first seconds, once they have primed the noise and are tracked), saves a
    checkpoint (see :mod:`wristtrack.pipeline.checkpoint`; also saved every
    ``checkpoint_every`` frames or 30 s, so a SIGKILL loses little), writes summary.json with
    ``"interrupted": true`` and raises KeyboardInterrupt. ``resume=True`` continues such a
    run in ``out`` from its checkpoint, in any pass, with the same result as an
    uninterrupted run.
    """
    detector_settings = detector_config(detector)  # an unknown name fails before any output
    out = _output_folder(out)
    config = config or TrackerConfig()
    passes = _Passes(config, labels, progress, smooth, checkpoint_every, detector,
                     detector_settings)
    surveyed = out / SURVEYED_HAND
    surveying = survey and recording.hand is None
    # with --smooth-noise learned, a smoothed run tracks once more at the motion noise it
    # shows (pipeline/refit.py), where the recording can be read again
    refitting = smooth and refits(config) and ckpt.input_identity(recording) is not None

    def run_pass(pass_config: TrackerConfig, folder: Path, again: bool) -> dict[str, Any]:
        one = replace(passes, config=pass_config, label="tracking at the learned noise")
        if surveying and surveyed.exists():
            with hand_of(recording, load_surveyed(surveyed)):
                return one.run(recording, folder, None, again, surveyed=True)
        return one.run(recording, folder, None, again)

    if resume and refit_begun(out):  # the refit's turn
        if not refitting:
            raise InputError(
                f"the run in {out} stopped while --smooth tracked it again at the learned noise; "
                "resume it with the options it was started with (--smooth, --smooth-noise "
                "learned) or track again without --resume"
            )
        return refit_run(out, config, None, run_pass, resume=True)
    if not resume:
        clear_refit(out)
    data = _passes(recording, out, passes, overlay, resume, surveyed, surveying)
    if refitting:
        return refit_run(out, config, data, run_pass, resume=False)
    return data


def _passes(recording: Recording, out: Path, passes: _Passes, overlay: Any, resume: bool,
            surveyed: Path, surveying: bool) -> dict[str, Any]:
    """The run's passes over ``recording``: with ``surveying``, a first that surveys the
    layout (into ``surveyed``) and a second that tracks with it; else the one."""
    if surveying and resume and surveyed.exists():  # the second pass's turn
        with hand_of(recording, load_surveyed(surveyed)):
            return passes.run(recording, out, overlay, second_pass_begun(out), surveyed=True)
    if not resume:
        surveyed.unlink(missing_ok=True)  # a previous run's
    if not (surveying and ckpt.input_identity(recording) is not None):
        return passes.run(recording, out, overlay, resume)
    run_survey = RunSurvey()
    # the overlay shows the final poses: the second pass's (it then always runs)
    data = passes.run(recording, out, None, resume, survey=run_survey)
    layout = run_survey.surveyed_layout()
    if layout is None:
        if overlay is None:
            return data  # nothing surveyed: the first pass is the run
        return passes.run(recording, out, overlay, False)
    write_json_atomic(surveyed, layout.to_dict())
    with hand_of(recording, layout):
        return passes.run(recording, out, overlay, False, surveyed=True)


@dataclass
class _Passes:
    """The settings every pass of one ``track_recording`` call shares."""

    config: TrackerConfig
    labels: Any
    progress: bool
    smooth: bool
    checkpoint_every: int
    detector: str
    detector_settings: DetectorConfig
    label: str = "tracking"  # the progress bar's, but for a survey's

    def run(self, recording: Recording, out: Path, overlay: Any, resume: bool,
            survey: RunSurvey | None = None, surveyed: bool = False) -> dict[str, Any]:
        """One pass over ``recording`` into ``out``: its summary. ``survey`` follows the
        tracker (a first pass); ``surveyed``: the recording carries the surveyed layout."""
        # the detector is a setting like the others: recorded, and part of the resume
        # fingerprint; so is the pass (its hand is the surveyed layout's)
        settings = {**settings_dict(self.config), "smoothed": bool(self.smooth),
                    "detector": self.detector,
                    "hand_layout_from": layout_origin(recording, survey, surveyed)}
        labels = self.labels
        manual_labels = None if labels is None else (
            labels.to_dict() if hasattr(labels, "to_dict") else np.asarray(labels).tolist()
        )
        fingerprint = ckpt.fingerprint(recording, {**settings, "labels": manual_labels})
        checkpoints = ckpt.Checkpointer(out, fingerprint, self.checkpoint_every)
        run, start = _open_run(recording, out, self.config, self.detector_settings,
                               fingerprint, resume, survey)
        # the run's own pass (not a survey's), fresh, of a recording that can be read twice
        # (one with a fingerprint: not a live camera)
        primed = (self.config.primes_noise and survey is None and not resume
                  and fingerprint is not None)
        prime = Priming(recording, self.config, self.detector_settings, labels,
                         self.progress) if primed else None
        bar = progress_bar(recording, self.progress,
                           "surveying the hand" if survey else self.label)
        bar.update(start)
        smooth = self.smooth  # a first pass too: it is the run if the survey finds nothing
        states = _state_writer(out, run.tracker, resume) if smooth else NoStates()
        files = [out / "poses.csv"] + ([out / STATES_FILE] if smooth else [])
        with PosesWriter(out / "poses.csv", append=resume) as writer, states:
            rows = Rows(writer, states, overlay, bar)
            try:
                interrupted = _frame_loop(recording, start, run, labels, rows, checkpoints,
                                          files, prime)
            finally:
                bar.close()
        return _finish(recording, out, run, self.config, settings, smooth, interrupted,
                       checkpoints)


# ------------------------------------------------------------------------------ opening


def _output_folder(out: str | Path) -> Path:
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:  # a file of that name, no permission, read-only disk
        raise InputError(
            f"cannot create the output folder {out} ({e.strerror}); give --out a folder you can "
            "write to"
        ) from None
    return out


def _open_run(
    recording: Recording,
    out: Path,
    config: TrackerConfig,
    detector: DetectorConfig,
    fingerprint: dict[str, Any] | None,
    resume: bool,
    survey: RunSurvey | None = None,
) -> tuple[RunState, int]:
    """The state to start from and the index of the first frame: a fresh run (a previous
    run's checkpoint and summary removed), or the checkpoint's, with the output files cut back
    to it (rows written after the checkpoint are redone). ``survey`` follows a first pass's
    tracker (a resumed one continues the checkpoint's, into ``survey``)."""
    if not resume:
        ckpt.clear_stale(out)
        tracker = Tracker(recording.camera, recording.hand, config)
        return (RunState(MarkerDetector(recording.camera, detector), tracker,
                          SummaryAccumulator(), survey=survey), 0)
    saved = ckpt.load_checkpoint(out, fingerprint)
    ckpt.truncate_outputs(out, saved)
    run = RunState(**saved.state)
    if survey is not None and run.survey is not None:
        survey.__dict__.update(run.survey.__dict__)  # the caller's object holds the survey
    run.survey = survey
    return run, saved.next_index


# ---------------------------------------------------------------------------- frame loop


def _frame_loop(
    recording: Recording,
    start: int,
    run: RunState,
    labels: Any,
    rows: Rows,
    checkpoints: ckpt.Checkpointer,
    files: list[Path],
    prime: Priming | None = None,
) -> bool:
    """Track the frames of ``recording`` from ``start`` one by one (the first seconds through
    ``prime``, which primes the tracker on them); True if the run was interrupted (Ctrl-C,
    SIGTERM)."""
    has_depth = recording.has_depth
    with DeferredInterrupt() as stop:
        try:
            with frames_ahead(recording, start) as frames:
                if prime is not None:
                    frames = prime(frames, run, rows)
                for frame in frames:
                    # Between two frames every object is consistent: the moment to checkpoint.
                    if stop.requested or checkpoints.due(frame.index):
                        rows.states.flush()  # poses.csv is flushed row by row
                        checkpoints.save(frame.index, files, run.saved())
                        if stop.requested:
                            return True
                    if came_without_depth(frame, has_depth):
                        run.without_depth.append(frame.index)
                    track_frame(frame, run, labels, rows)
                    rows.bar.update(1)
        except KeyboardInterrupt:  # a second Ctrl-C: the last periodic checkpoint stands
            return True
    return False


# ------------------------------------------------------------------------------ finishing


def _finish(
    recording: Recording,
    out: Path,
    run: RunState,
    config: TrackerConfig,
    settings: dict[str, Any],
    smooth: bool,
    interrupted: bool,
    checkpoints: ckpt.Checkpointer,
) -> dict[str, Any]:
    """Smoothing (if asked for and the run is complete), then summary.json with the kinematics
    of the final poses.csv. An interrupted run raises KeyboardInterrupt once its summary is
    written; a run that never initialised raises InitialisationError."""
    tracker, summary = run.tracker, run.summary
    if smooth and not interrupted:
        checkpoints.discard()  # smoothing rewrites poses.csv: the checkpoint's sizes lapse
        if tracker.R_c0 is not None:
            summary = _smoothed_summary(out, tracker, config)
    data = summary.to_dict(
        hand_layout=tracker.layout.to_dict() if tracker.layout is not None else None,
        camera_pose_w0=camera_pose_dict(tracker.R_c0, tracker.t_c0),
        camera=recording.camera.to_dict(),
        source=str(recording.source),
        settings=settings,
        skipped_frames=run.bad_frames,
        frames_without_depth=run.without_depth,
        # what the source and the tracker must say about the poses, e.g. an unresolved planar
        # flip, a rolling shutter of unknown readout
        warnings=[*getattr(recording, "warnings", []), *getattr(tracker, "warnings", [])],
        # the markers' noise as the recording showed it (tracking/noise_scale.py)
        measurement_noise=tracker.learned_noise.describe(config.measurement),
        depth_registration=tracker.depth_registration,  # --follow-offset's estimate, else None
        # each depth frame's capture after its colour frame (tracking/depth_timing.py)
        depth_timing=tracker.depth_timing.to_dict(),
        interrupted=interrupted,
        # Read back from disk: poses.csv is final here (smoothed, if asked for).
        kinematics=analyse_file(out / "poses.csv"),
    )
    write_json_atomic(out / "summary.json", data)
    for warning in data["warnings"]:
        print(f"wristtrack: warning: {warning}", file=sys.stderr)
    if interrupted:
        raise KeyboardInterrupt
    checkpoints.discard()  # complete
    if tracker.R_c0 is None:  # the outputs say so too, but a run with no pose is a failure
        raise InitialisationError(no_initialisation_message(recording, summary.frames, tracker))
    return data


def _smoothed_summary(out: Path, tracker: Tracker, config: TrackerConfig) -> SummaryAccumulator:
    """Smooth the run in ``out``; the summary of the smoothed poses."""
    summary = SummaryAccumulator()
    for result in smooth_run(out, tracker.model, config.ukf, tracker.layout.side,
                             config.coast_limit):
        summary.add(result)
    return summary


# -------------------------------------------------------------------------------- helpers


def no_initialisation_message(recording: Recording, n_frames: int, tracker: Tracker) -> str:
    """Why no frame of the run gave a first pose, in one line."""
    reason = tracker.last_init_error or "no frame could be read"
    if tracker.max_blobs_seen < 6:
        reason = (
            f"no frame showed all six markers (at most {tracker.max_blobs_seen} blobs in one "
            "frame); start the recording with the back of the hand, all six markers in view, "
            "check the lighting and the marker colour"
        )
    return (
        f"no frame of {recording.source} could be initialised (none of {n_frames} frames gave "
        f"a pose): {reason}; poses.csv and summary.json record the frames"
    )


def settings_dict(config: TrackerConfig) -> dict[str, Any]:
    def clean(value):
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, tuple | list):
            return [clean(v) for v in value]
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    # and whether the model can use camera.json's readout_s and each depth frame's delay
    return {**clean(asdict(config)), "timing_modelled": reads_camera_timing(config.model)}


def _state_writer(out: Path, tracker: Tracker, append: bool = False) -> StateWriter:
    """The per-frame filter states the smoother needs, streamed beside poses.csv."""
    model = tracker.model
    state_dim = model.initial_state(np.eye(3), np.zeros(3)).size
    return StateWriter(out / STATES_FILE, state_dim, model.dim, append=append)
