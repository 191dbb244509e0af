"""Studies: many scenarios sampled from distributions over one base scenario.

A study file (``studies/<name>.toml``, docs/studies.md) names a base scenario and
distributions over its fields, addressed by the ``--set`` keys; :mod:`sweep.study`
reads and validates it, :mod:`sweep.sampler` draws reproducible samples and turns each
into a validated scenario through the normal loader.
"""
