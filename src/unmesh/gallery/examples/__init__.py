"""The gallery's examples, one module per topic, run on built-in data.

``sampling`` (surfels: sampling and estimation), ``mls``, ``render``, ``shells``,
``sph`` and ``fem``. Each module registers its examples with
:func:`unmesh.gallery.registry.example`; :data:`unmesh.gallery.EXAMPLE_MODULES` lists
them in page order. Helpers used only by the examples live here too; library
functionality they use comes from the capabilities, which never import the gallery.
"""
