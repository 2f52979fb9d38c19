"""The run's recording as actors see it: the recorder actor and its MCAP writer service, the batching
recorder of every other actor, and the forwarding of a node recorder's messages to the driver's live view."""
