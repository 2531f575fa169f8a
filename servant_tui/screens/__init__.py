"""The application's screens: live (default), teach, library, settings, help, and its dialogs."""
