"""The senses Servant has, by name, and what the generic parts need to know of each.

Sound and pictures have their own paths through the engine; every other sense is a *sample
sense*: readings (n, channels) at a fixed rate, cut into windows as long as the sound's, each judged
by its recogniser. The engine's loop, the library, the model file, retrain and the TUI work from
this registry: a new sample sense is its stream (`capture.sensors.STREAMS` or any `SampleSource`),
features and recogniser class (`sense` = its name), and one line in `SENSES` (`"module:Class"`).
"""

from __future__ import annotations

from dataclasses import dataclass

AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")
# The scene a recogniser names when it knows none: never a scene folder's name. It lives here,
# below both the scene library and the recognisers, so that the library need not import the
# recognisers (whose registry imports capture, whose replay imports the library).
UNKNOWN = "<unknown>"
CENTROIDS = "servant_core.recognisers.sensor_centroids"
SAMPLE_METHOD = "kmeans"  # the method name a sample sense's recogniser is registered under


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
    # a sample sense's recogniser as "module:Class", registered as its method `kmeans`
    recogniser: str | None = None

    @property
    def sampled(self) -> bool:
        return self.stream is not None


def sample_sense(name: str, stream: str, label: str, recogniser: str) -> Sense:
    """A sense read from a sensor stream, its library files `*.<stream>.csv`, judged by the
    `recogniser` class ("module:Class")."""
    return Sense(name, name, stream, (f".{stream}.csv",), stream, label, recogniser)


SENSES: dict[str, Sense] = {
    s.name: s
    for s in (
        Sense("audio", "acoustic", "microphone", AUDIO_SUFFIXES, label="sound"),
        Sense("image", "visual", "camera", PICTURE_SUFFIXES, label="pictures"),
        sample_sense("motion", "imu", "motion", f"{CENTROIDS}:MotionRecogniser"),
        sample_sense(
            "ambient", "ambient", "light, temperature, pressure", f"{CENTROIDS}:AmbientRecogniser"
        ),
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
