"""Navigation actors, one per role: the mapper explores and uploads
(``mapper``), the hider drives to its spot (``hider``), the seeker drives to a
guess and confirms with its IR sensor (``seeker``); ``base`` is what the three
share (the ADP step loop, route following, recovery) and ``factory`` builds the
actor for a role."""
