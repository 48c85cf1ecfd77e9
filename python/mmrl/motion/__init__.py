"""Motion data, offline: BVH import and export (``bvh``), the immutable Database and its features
(``database``), exact nearest-neighbour search (``search``), where a database comes from
(``sources``), datasets and their cache (``data``) and the synthetic locomotion that is the default
data (``synth``, ``synth_motion``)."""
