"""The live view's pure parts (no ROS): what the ``live_view`` node shows, as JSON-ready messages.

``plot``: the force–displacement points of the current fit segment (decimated for display), the fit lines with
their 95 % band, the prediction line, the estimate and the status; ``scene``: the crane as a ``foxglove.SceneUpdate``;
``msgdefs``: ROS 2 message definitions as Foxglove clients want them; ``web/``: the page the node serves.
"""
