"""Driver actors: one per seed thread or ISR that talks to a device.

``motor`` (Motor Control: closed-loop PWM on the treads from encoder distance),
``lidar`` (LIDAR Control: Command B, Data Packet A), ``ir`` (the IR thread),
``wifly`` (the WiFly thread: the JSON message layer's link end) and ``isr``
(the five interrupt service routines, Int A-E, posting to those mailboxes).
"""
