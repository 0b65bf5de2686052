"""The JSON Schemas of the superbody messages.

Generated from the typed message definitions by ``python -m superbody.host.messages.schemas --write``
(never edited by hand); this folder installs as the data package ``superbody.schemas`` so that
an installed wheel finds the same files (``superbody.edge.resources.json_schema``). Nothing to
import here.
"""
