"""The test harness: the headless runner (``headless``: one whole game in
virtual time, the operator's choices taken from the scenario), the invariants
checked on every game (``invariants``) and seeded campaigns of many games
under faults (``campaign``). Not part of a rover or the server."""
