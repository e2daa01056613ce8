"""Where a rover is: pose algebra and dead reckoning (``odometry``) and the
contact measurement that places a rover stopped against a mapped wall
(``contact``)."""
