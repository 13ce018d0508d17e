"""The robot agent: a simulation engine (:mod:`.engine`) and the TCP host on top of it (:mod:`.host`).

The wire contract they speak lives in the top-level :mod:`contract` package.
"""
