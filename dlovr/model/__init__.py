"""The paper's contact model, pure: no simulator, no mesh library, no UI, no file format.

- :mod:`dlovr.model.topology`: topological contact situations (paper §III): primitives, contacts,
  contraction, notation.
- :mod:`dlovr.model.discrete`: discrete contact states (§IV): card (eq. 3), contact vectors (eq. 2),
  stability.
- :mod:`dlovr.model.transitions`: principal contacts, matching and transition classes (§V), and the
  debouncing of a simulated sequence.
- :mod:`dlovr.model.program`: macro programs compiled from a demonstration (§VI).
- :mod:`dlovr.model.program_format`: the one :class:`~dlovr.model.program_format.Program` type, which
  writes and reads ``*.program.json`` (its schema shipped in ``dlovr/data/``) and is what the
  execution engine runs; the :class:`~dlovr.model.program_format.Runnable` protocol it shares with
  network programs.
- :mod:`dlovr.model.network`: transition networks merged from several demonstrations (§VI, §VII).
- :mod:`dlovr.model.planning`: network programs: the macro toward the goal at every node, identifying
  the node reached and planning again (§VI); :func:`~dlovr.model.planning.load_runnable` reads a
  program file of either kind, once.
- :mod:`dlovr.model.sequence`: sequences of situations written one per line, untimed or timed.

Everything here imports only the standard library, numpy and networkx (a test checks that no simulator,
mesh, UI or file-format library is), so the model is tested and reused without a simulator. See
``docs/model.md`` for the rules in words.
"""
