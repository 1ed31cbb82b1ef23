"""beaconloc-view's tests: the state model on encoded MAVLink (test_view_state.py) and the
page in headless Chromium during a paced bridge replay (test_view_browser.py)."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
