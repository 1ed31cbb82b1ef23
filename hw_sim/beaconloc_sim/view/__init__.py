"""beaconloc-view: the live map (docs/view.md)."""
