"""engine: the machinery that runs the JAX core, apart from the physics it runs.

* :mod:`~vibid.identify.engine.runtime`: 64-bit JAX, one BLAS thread, the persistent
  compilation cache, switched on by the entry points (:func:`runtime.configure`);
* :mod:`~vibid.identify.engine.compiled`: the bounded cache of a model structure's compiled
  functions, handed to the models that share the structure;
* :mod:`~vibid.identify.engine.persist`: traced programs kept on disk for the next process;
* :mod:`~vibid.identify.engine.threads`: independent work on the second core, one compiled
  program at a time (the JAX turn);
* :mod:`~vibid.identify.engine.profile`: where an identification's time goes.
"""
