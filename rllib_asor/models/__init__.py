"""RLModules for our observation spaces (the race network)."""
