"""The mapper's map: the occupancy grid, Map Management (the seed's thread) and
the scan matching that places each LIDAR revolution on the map being built."""
