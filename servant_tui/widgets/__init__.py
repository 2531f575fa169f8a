"""The panes of the live and teach screens; each shows one kind of engine event."""
