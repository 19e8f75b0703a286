"""The experiments: one analysis per chapter or paper (a module or a package named as
configs name it, found by :data:`estim.config.registry.ANALYSES`), and in :mod:`.shared`
what several of them use: the per-run scoring pipeline, filter health, claims, tuning,
shared config blocks and figures. :mod:`.base` states the protocol every analysis follows.
"""
