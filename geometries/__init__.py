"""ngat's scenes, one file each, installed as ``ngat.geometries``; ``ngat scenes`` lists them."""
