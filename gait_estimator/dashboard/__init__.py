"""The live web view of a running estimator_node (``gait-estimator dashboard``): an aiohttp
server beside the node that serves one page and pushes the node's state to it over a WebSocket.

The ROS side is ``gait_estimator.ros.dashboard_client`` (only it touches rclpy); this layer adds
the web server, the checks on what a page may ask, and the page itself (``static/``, no asset from
the internet). Imports ``core``, ``io``, ``analysis`` and ``ros``; never ``cli``.
"""
