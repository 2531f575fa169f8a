"""The senses Servant has, by name, and what the generic parts need to know of each.

A sense is a source (a device or a file replay), features and a recogniser. Sound and pictures
have their own paths through the engine (spectra, pictures on demand); every other sense is a
*sample sense*: a stream of readings (n, channels) at a fixed rate, cut into windows of the same
length as the sound's, each judged by its recogniser. The engine's loop, the scene library, the
model file, retrain and the TUI work from this registry, so a new sample sense is:

1. its stream on the sensor board (`capture.sensors.STREAMS`) or any `SampleSource`, its
   features and its recogniser class (registered as a method for its sense name in
   `recognisers.SENSE_METHODS`);
2. one line in `SENSES` below.
"""

from __future__ import annotations

from dataclasses import dataclass

from servant_core.audio import AUDIO_SUFFIXES

PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True)
class Sense:
    """`name`: the recognisers' sense; `role`: its key in model files and scores; `device`: its
    device in statuses; `suffixes`: its files in a scene library (`ROOT/<scene>/`); `stream`:
    for a sample sense, the sensor stream it reads ("imu"), None for sound and pictures. (The
    method a first retrain fits is `recognisers.FRESH_METHODS[name]`.)"""

    name: str
    role: str
    device: str
    suffixes: tuple[str, ...]
    stream: str | None = None
    label: str = ""

    @property
    def sampled(self) -> bool:
        return self.stream is not None


def sample_sense(name: str, stream: str, label: str) -> Sense:
    """A sense read from a sensor stream, its library files `*.<stream>.csv`."""
    return Sense(name, name, stream, (f".{stream}.csv",), stream, label)


SENSES: dict[str, Sense] = {
    s.name: s
    for s in (
        Sense("audio", "acoustic", "microphone", AUDIO_SUFFIXES, label="sound"),
        Sense("image", "visual", "camera", PICTURE_SUFFIXES, label="pictures"),
        sample_sense("motion", "imu", "motion"),
        sample_sense("ambient", "ambient", "light, temperature, pressure"),
    )
}
SAMPLE_SENSES = {name: s for name, s in SENSES.items() if s.sampled}
ROLE_SENSE = {s.role: s.name for s in SENSES.values()}


def sense_of_file(name: str) -> Sense | None:
    """The sense whose library files end like `name` (case-insensitive), or None."""
    lower = name.lower()
    for sense in SENSES.values():
        if any(lower.endswith(suffix) for suffix in sense.suffixes):
            return sense
    return None
