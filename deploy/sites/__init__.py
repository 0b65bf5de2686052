"""The site files shipped with superbody.

This folder is where sites live in the repository and where users copy one from; it installs
as the data package ``superbody.sites`` so that an installed wheel finds the same files
(``superbody.edge.resources.site_path``). Nothing to import here.
"""
