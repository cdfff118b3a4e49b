"""The ``lessmimic`` command (:mod:`lessmimic.cli`): the entry point above every stage, so that
:mod:`pipeline` (the shared core) imports none of them."""
