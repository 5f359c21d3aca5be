"""Site aggregation: overlapping scenes become one site, night scenes are dropped, stationary clips merged."""
