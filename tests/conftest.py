"""Test set-up: headless SDL for every test (the library itself never sets environment variables)."""

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
