"""The wire between a companion and its vehicle, with no simulator in it: MAVLink 2 over UDP with
several peers (:mod:`landfall_link.mavlink`) and the sensor-frame stream (:mod:`landfall_link.sensorstream`:
its protocol, client and server). The companion imports these and nothing of simbridge; simbridge serves
the same stream from its world."""
