"""The rovers' firmware as actors: the seed's threads, ISRs and queues.

One subpackage per concern (each imports only those above it)::

    hardware, commands, addresses   the device contract (ISR boundary), the internal
                                    command codes, the record of a rover's actor names
    localisation/                   dead reckoning and contact geometry (pure)
    mapping/, planning/             occupancy grid, scan matching; planner, clearance,
                                    frontiers (pure algorithms on grids)
    drivers/                        the five ISRs (Int A-E) and the driver actors:
                                    motor, lidar, ir, wifly (wifly also uses server.protocol)
    nav/                            navigation actors (mapping, hiding, seeking)
    fault_port, telemetry           the failure-injection hook the WiFly answers faults
                                    from; the telemetry task that reads the rover's runtime

The package never imports ``world``, and of ``server`` only ``server.protocol``
(tests/test_layers.py). This ``__init__`` imports nothing, so that the world
can import the device contract ``actors.firmware.hardware`` without loading
the firmware. The supervision trees live in ``supervisors.rover``.
"""
