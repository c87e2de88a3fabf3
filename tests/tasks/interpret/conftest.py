"""Fixtures of the model tests here: no model API key in the environment (no test reaches a real model)
and a local OpenAI-compatible fake server on 127.0.0.1 (:mod:`tests.fake_openai_server`)."""

from tests.fake_openai_server import no_keys, server  # noqa: F401  (fixtures)
