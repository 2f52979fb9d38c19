"""Analytics inside an actor: one analytics object fed item by item (a colocated analytics or one replica of
a deployed one)."""
