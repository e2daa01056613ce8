"""Navigation actors, one per role, and what they share.

One actor per rover owns its parts (none inherits another):
``base`` (`NavBase`: messages, pose, origin) with ``controller`` (the ADP
loop's motion in flight); ``route_nav`` (`RouteNav`: the hider's and seeker's
actor, on the server's map) with ``localiser`` (the pose belief),
``tread_faults`` (what a tread report does), ``recovery`` (the recovery
behaviours of a blocked route), ``nudge_series`` and ``nudge`` (the sideways
search's state and geometry) and the role behaviours ``role``, ``hider``
(`Hide`) and ``seeker`` (`Seek`, with ``search``); the mapper (``mapper``,
`MappingNav`) with ``exploration``, ``homing``, ``sensor_watch`` and
``mapping_options``; ``options`` (tunables and the retained record), ``route``
(planning and following a route, pure); and ``factory``, which builds the
actor for a role."""
