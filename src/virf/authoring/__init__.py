"""Knowledge acquisition: from safety documents to reviewed, evidence-cited axioms.

The paper's Traceable Axiom Synthesis workflow as a tool: a workspace with a
corpus and hybrid retrieval, LLM (or human) drafts, automatic normalisation
and logical checks, human arbitration on a review page or the terminal, and
an audit of the funnel.  Accepted axioms land in the workspace's layered
modules, which ``--kb DIR`` adds to the built-in TBox.
"""
