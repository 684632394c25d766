"""LeafSystems of the station and the controllers."""
