"""Files and streams: kernel library formats, recordings (CSV, rosbag2), input checks for
streamed samples, output layouts shared by the node and the bag writer, bundled data.

Imports ``core``; never ``analysis``, ``ros`` or ``cli``.
"""
