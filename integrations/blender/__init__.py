"""The Blender add-on (``segue_blender``) and what packs it (``segue blender-addon``)."""
