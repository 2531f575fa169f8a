"""Feature extraction: pure functions from windows and pictures to vectors."""
