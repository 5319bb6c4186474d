"""ngat's scenes, one file each; ``ngat scenes`` lists them, ``ngat run NAME`` runs one."""
