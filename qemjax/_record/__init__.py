"""What a run returns: the result object and the replayable multiresolution record."""
