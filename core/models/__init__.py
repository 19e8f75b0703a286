"""Circuit and field models sharing the interface of :class:`estim.models.base.Model`."""
