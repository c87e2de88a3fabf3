"""The model client, a wing of the core on litellm: :mod:`.client` (``LLMClient``: the retry loop,
the reply cache, re-asking), :mod:`.transport` (litellm imported on first use, every attempt bounded
by a deadline and a reply size cap), :mod:`.replies` (strict reply parsing), :mod:`.config`,
:mod:`.errors`, :mod:`.usage`. The stages that ask models (the estimators, the model parse of the
request) and the realism judge import it; it imports nothing above the core. Design:
``docs/design/model_backends.md``.
"""
