"""The engine's senses: microphone, camera, and replayed files, behind one small interface.

Importing this package never touches PortAudio: the microphone loads sounddevice when opened.
"""

from servant_core.capture.camera import Camera
from servant_core.capture.microphone import Microphone, find_input_device, list_input_devices
from servant_core.capture.replay import Clip, PacedAudio, PictureReplay, replay_recordings
from servant_core.capture.ring import RingBuffer
from servant_core.capture.source import AudioSource, FrameSource, ManualClock, MonotonicClock

__all__ = [
    "AudioSource",
    "Camera",
    "Clip",
    "FrameSource",
    "ManualClock",
    "Microphone",
    "MonotonicClock",
    "PacedAudio",
    "PictureReplay",
    "RingBuffer",
    "find_input_device",
    "list_input_devices",
    "replay_recordings",
]
