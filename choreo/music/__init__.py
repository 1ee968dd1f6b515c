"""Music: the player whose position is the show clock, and `choreo beats`' beat finding."""
