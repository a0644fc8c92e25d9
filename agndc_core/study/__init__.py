"""The research wing: evaluation against ground truth (``evaluate``), the results page
(``report``), symmetry and geometric measurements (``symmetry``, ``solids``) and the procedural
shape generator (``shapes``) that training and evaluation draw from. Not part of the product path
(I/O -> voxelise -> network -> contour -> filters) and not shipped in the Blender extension."""
