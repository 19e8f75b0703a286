"""Circuit and field models sharing the interface of :class:`core.models.base.Model`."""
