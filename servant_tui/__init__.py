"""Servant's terminal application (Textual), over the engine in `servant_core`."""
