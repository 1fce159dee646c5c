"""Real-time tracking of a live source: the loop, the `--view` server and its page."""
