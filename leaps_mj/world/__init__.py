"""World: the houses themselves, before any agent is in them.

Room types and object classes (:mod:`rooms`), the house data model
(:mod:`houses`), the generator (:mod:`generator`, with the furniture stage in
:mod:`furnish`), MJCF (:mod:`mjcf`), dataset files and manifests
(:mod:`dataset`), the navigation grid and geodesics (:mod:`navgrid`), house
statistics against the reference (:mod:`stats`) and top-down drawing
(:mod:`topdown`). The bottom stage: it imports nothing else of the package.
"""
