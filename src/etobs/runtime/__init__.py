"""Deployment: sensor nodes and a remote observer service over a real network.

The sensor side (:mod:`~etobs.runtime.packet`, :mod:`~etobs.runtime.sampled_rule`,
:mod:`~etobs.runtime.sensor`) uses the Python standard library alone, so that it runs
on small devices; the observer service (:mod:`~etobs.runtime.service`) uses numpy.
Nothing is imported here.
"""
