"""Navigation actors, one per role, and what they share.

``base`` (`NavBase`: messages, pose, the ADP step loop) with ``tread_faults``
(what a tread-fault report does, and the pose doubt it leaves),
``options`` (tunables and the retained record), ``route`` (planning and
following a route, pure), ``route_nav`` (`RouteNav`: the hider's and seeker's
base, on the server's map) with ``recovery`` (what a blocked route does)
and ``nudge`` (the geometry of its sideways search, pure);
the mapper (``mapper``) with ``exploration``, ``homing``, ``sensor_watch`` and
``mapping_options``; the hider (``hider``); the seeker (``seeker``); and
``factory``, which builds the actor for a role."""
