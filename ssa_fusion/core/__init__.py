"""The reusable maths of ssa_fusion, in rooms by what they model (no ROS, no file formats).

Usable without ROS, as FilterPy or PyDMD are: it imports numpy, scipy, sgp4, numba, pyerfa,
jplephem and astropy-iers-data, never rclpy, lxml, YAML or another floor of the package.
Units throughout: km, km/s, rad, s; inertial states in the GCRF, Earth-fixed in the ITRF,
Unix seconds (UTC) as epochs. Each room imports only itself and the rooms below it, bottom
up (`test/test_layers.py`'s ``CORE_ROOMS``):

* `base`: types, constants, compiled-loop support, rows of many measurements, metrics;
* `earth`: time scales, Earth orientation, frames, refraction, the Sun, light time,
  stations and their visibility;
* `motion`: dynamics, Keplerian motion, propagation with the state transition matrix, force
  models, element sets and their SGP4 states;
* `measure`: measurement models, input validation, initial orbit determination, passes;
* `filter`: EKF, UKF, smoother, track initiation, the one-object tracker and its options,
  process noise;
* `od`: batch least-squares orbit determination (Gauss-Newton);
* `gaps`: forecasting through sensor gaps: Hankel-DMD surrogate, learned residuals, batch
  gap fits, what the filter publishes in a gap, the estimator's settings;
* `catalog`: many objects at once: the batched EKF, track and gap banks, association of
  unlabelled detections;
* `conjunction`: close approaches between objects and their collision probability.
"""
