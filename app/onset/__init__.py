"""The onset workflow: crossing detection and bisection, wrinkle counting."""
