"""Step 2 of teach mode: windows of the place's sound, with the sample senses' same seconds."""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from textual import on, work
from textual.app import ComposeResult
from textual.widgets import Button, Label, ProgressBar, Static
from textual.worker import get_current_worker

from servant_core.audio import DEFAULT_WINDOW_SECONDS
from servant_core.capture.sensors import CHANNELS
from servant_core.errors import ServantError
from servant_core.library import TEACH_WINDOWS, SceneLibrary, teach_stem
from servant_core.senses import SENSES
from servant_tui.messages import RecordingDone, RecordingStopped
from servant_tui.screens.teach.step import TeachStep, every_press
from servant_tui.widgets.spectrum import Spectrum

# A sample sense records the same seconds as the sound; one whose readings stopped says so this
# long after the sound has been recorded.
SAMPLE_GRACE_SECONDS = 2.0


class SoundStep(TeachStep):
    """*Record 5 s* records a window of sound into the scene library, `TEACH_WINDOWS` of them
    asked for; the live spectrum shows what is heard meanwhile."""

    STATUS = "#sound-status"

    def __init__(self, spectrum: Spectrum, *, id: str) -> None:
        super().__init__(id=id)
        self.spectrum = spectrum
        self.windows = 0  # recorded for the scene taught
        self._recording_started: float | None = None

    def sample_senses(self) -> list[str]:
        """The engine's sample senses (motion, ambient): recorded with the sound."""
        return list(self.app.engine.sample_senses)

    def compose(self) -> ComposeResult:
        senses = self.sample_senses()
        with_senses = f", with its {' and '.join(senses)}" if senses else ""
        yield Label(
            f"Record {DEFAULT_WINDOW_SECONDS:g} s of the place's sound"
            f"{with_senses}, {TEACH_WINDOWS} times: the place is recognised "
            f"far more often from {TEACH_WINDOWS * DEFAULT_WINDOW_SECONDS:g} s than "
            "from a few."
        )
        yield every_press(
            Button(f"Record {DEFAULT_WINDOW_SECONDS:g} s", id="record", variant="primary")
        )
        yield ProgressBar(total=DEFAULT_WINDOW_SECONDS, show_eta=False, id="record-progress")
        yield self.spectrum
        yield Static(id="sound-status")

    def on_mount(self) -> None:
        self.set_interval(0.1, self._tick_recording, pause=False)

    def start_again(self) -> None:
        self.windows = 0

    @on(Button.Pressed, "#record")
    def start_recording(self) -> None:
        scene = self.attempt(self.wizard.need_scene)
        if scene is None:
            return
        self.query_one("#record", Button).disabled = True
        self._recording_started = time.monotonic()
        self.record(scene)

    def _tick_recording(self) -> None:
        if self._recording_started is not None:
            elapsed = time.monotonic() - self._recording_started
            self.query_one("#record-progress", ProgressBar).update(
                progress=min(elapsed, DEFAULT_WINDOW_SECONDS)
            )

    @work(thread=True, exclusive=True, group="record", exit_on_error=False)
    def record(self, scene: str) -> None:
        """The next seconds of sound into `<scene>/teach-….wav`, and the same seconds of each
        sample sense beside it (`….imu.csv`, `….ambient.csv`), each sense on a thread of its
        own. A sensor that fails loses only its own log: the sound is kept, and the failure is
        one line in the log and a notification. Teach mode closing (Escape, or the app quitting)
        stops the recording at once: nothing of a stopped recording is written, and the screen,
        gone, is not touched again: the app says so in the log."""
        stop = get_current_worker().cancelled_event
        app = self.app  # a screen that has gone no longer knows its app
        engine = app.engine
        senses = self.sample_senses()
        library, stem = SceneLibrary.at(app.library_root), teach_stem()
        try:
            with ThreadPoolExecutor(max(len(senses), 1), thread_name_prefix="teach") as pool:
                feeling = {
                    sense: pool.submit(
                        engine.record_samples,
                        sense,
                        DEFAULT_WINDOW_SECONDS,
                        DEFAULT_WINDOW_SECONDS + SAMPLE_GRACE_SECONDS,
                        stop,
                    )
                    for sense in senses
                }
                sound = engine.record_window(DEFAULT_WINDOW_SECONDS, cancel=stop)
                if stop.is_set():  # in full as teach mode closed: it is not kept either
                    raise ServantError("teach: closed while recording")
                audio = np.asarray(sound, dtype=np.float32)
                rate = engine.audio_rate
                path = library.add_recording(scene, audio, rate, stem)
                logs = [self._add_log(library, path, s, f, stop) for s, f in feeling.items()]
        except ServantError:
            if stop.is_set():
                app.post_message(RecordingStopped(scene))
                return
            raise
        finally:
            if not stop.is_set():
                app.call_from_thread(self._recording_over)
        written = tuple(log for log in logs if log is not None)
        self.post_message(RecordingDone(path, len(audio) / rate, written))

    def _add_log(
        self,
        library: SceneLibrary,
        sound: Path,
        sense: str,
        recording: Future[Any],
        stop: threading.Event,
    ) -> Path | None:
        """Add a sample sense's recording to the library beside the sound, under its name;
        None (said in one line) if the sensor failed, or (not said: the screen is going) if
        teach mode closed meanwhile."""
        try:
            rows, rate = recording.result()
        except ServantError as error:
            if not stop.is_set():
                self.app.call_from_thread(
                    self.app.report_error,
                    ServantError(
                        f"{sense}: not recorded ({error}); the sound {sound.name} was kept"
                    ),
                )
            return None
        channels = CHANNELS[str(SENSES[sense].stream)]
        return library.add_samples(sound.parent.name, sense, rows, rate, channels, sound.stem)

    def _recording_over(self) -> None:
        """The button back, and the focus on it while the sound step shows: disabling it took
        the focus away, and Enter (record another) then did nothing."""
        self._recording_started = None
        record = self.query_one("#record", Button)
        record.disabled = False
        if self.shown():
            record.focus()

    @on(RecordingDone)
    def recorded(self, message: RecordingDone) -> None:
        self.windows += 1
        self.query_one("#record-progress", ProgressBar).update(progress=DEFAULT_WINDOW_SECONDS)
        logs = ", ".join(p.name for p in message.samples)
        left = TEACH_WINDOWS - self.windows
        more = f", {left} more to go" if left > 0 else ""
        self.query_one("#sound-status", Static).update(
            f"{self.windows} window(s) recorded{more}; last: {message.path.name} "
            f"({message.seconds:.1f} s)" + (f" with {logs}" if logs else "")
        )
        for path in (message.path, *message.samples):
            self.app.log_line(None, f"recorded {path}")
