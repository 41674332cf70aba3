#!/usr/bin/python3
"""Imports the installed Python package from the prefix given and drives a filter a few steps.

Usage: python_import.py PREFIX (with PYTHONPATH at PREFIX's dist-packages). Fails unless the
module comes from PREFIX, so a copy in the build tree or the system cannot stand in for it.
"""
import math
import sys

import fastslam

prefix = sys.argv[1]
if not fastslam.__file__.startswith(prefix):
    sys.exit("fastslam imported from %s, not from %s" % (fastslam.__file__, prefix))
f = fastslam.Filter(particles=20, seed=3)
for t in range(1, 9):
    dx, dy = 10.0 - t, 5.0
    f.predict([1.0, 0.0], 1.0)
    f.observe([math.hypot(dx, dy)], [math.atan2(dy, dx)], ids=[0])
e = f.estimate()
if e.map.size != 1 or math.hypot(e.map["x"][0] - 10.0, e.map["y"][0] - 5.0) > 3.0:
    sys.exit("the filter did not map the landmark: %r" % (e.map,))
print("python import: ok (%s, landmark at %.2f, %.2f)" % (fastslam.__file__, e.map["x"][0],
                                                          e.map["y"][0]))
