"""The mapper's map: the map snapshot every reader uses (``grid_map``), the
log-odds occupancy grid (``occupancy``; the cells its rays cross, ``ray_samples``),
Map Management, the seed's thread (``map_management``), and the scan matching that
places each LIDAR revolution on the map being built (``scan_match``)."""
