"""Teach mode, step by step: scene, sound, pictures, pose, (repeat), train, test.

Each step is a widget of its own module; `TeachScreen` shows one at a time and keeps what they
share. Recordings and pictures go straight into the scene library (nothing is lost if the
session ends); each pose becomes a teach record. Training shows the action learner's error
falling as it goes.
"""

from servant_tui.screens.teach.scene import KnownScenes
from servant_tui.screens.teach.screen import TeachScreen

__all__ = ["KnownScenes", "TeachScreen"]
