"""Servant's engine: capture, features, recognisers, fusion, actions and the servo link.

Importing this package never imports Textual and never fails for want of a device.
"""

__version__ = "0.1.0"
