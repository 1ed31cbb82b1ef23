"""beaconloc hardware simulator."""
