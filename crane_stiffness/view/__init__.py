"""The live view's pure parts (no ROS): what the ``live_view`` node shows, as JSON-ready messages.

``plot``: the force–displacement points of the current fit segment (decimated for display), the fit lines with
their 95 % band, the prediction line, the estimate and the status; ``scene``: the crane as a ``foxglove.SceneUpdate``;
``msgdefs``: ROS 2 message definitions as Foxglove clients want them; ``server``: the Foxglove WebSocket server and
the page's HTTP server; ``access``: who may use them (Origin, Host, the token); ``front``: the WebSocket front on the
public port that checks each handshake and answers the service calls (``wsframes``: the WebSocket frames it reads);
``web/``: the page the node serves.
"""
