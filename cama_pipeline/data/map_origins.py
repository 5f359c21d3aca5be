"""Where nuScenes' map frames lie on the Earth: the geographic origin of each location's global frame.

nuScenes places every `log.location` in a global frame of its own (x east, y north, metres), a local tangent frame
whose (0, 0) is a per-location reference point; the devkit publishes those four points (its pose-export script's
reference coordinates) and derives latitude and longitude from them. An export that geolocates a site of one of
these locations (Lanelet2's lat / lon) takes the origin from here and projects with a local tangent frame there, not
with the UTM grid: at boston-seaport the grid is turned about 1.4 degrees from true north (the meridian convergence
of UTM zone 19), which would rotate the map by that (25 m at 1 km).

A location not listed here (the generator's `synthetic-*` and `synth-random-*`, any other data set's) has no known
origin: the user gives one.
"""

NUSCENES_MAP_ORIGINS: dict[str, tuple[float, float]] = {
    "boston-seaport": (42.336849169438615, -71.05785369873047),
    "singapore-onenorth": (1.2882100868743724, 103.78475189208984),
    "singapore-hollandvillage": (1.2993652317780957, 103.78217697143555),
    "singapore-queenstown": (1.2782562240223188, 103.76741409301758),
}
"""nuScenes `log.location` -> (latitude, longitude) in degrees of its global frame's (0, 0)."""


def location_origin(location: str) -> tuple[float, float] | None:
    """The geographic origin of a nuScenes location's global frame, or None for a location without one."""
    return NUSCENES_MAP_ORIGINS.get(location)
