"""Fixtures of the synthesis tests: no model API key in the environment (no test reaches a real model) and
a local OpenAI-compatible fake server on 127.0.0.1 (:mod:`tests.fake_openai_server`)."""

from __future__ import annotations

import pytest

from tests import fake_openai_server as fake

#: The environment variables litellm reads a provider's key from.
MODEL_KEYS = ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "ANTHROPIC_API_KEY")


@pytest.fixture(autouse=True)
def no_keys(monkeypatch):
    """No provider key in the environment."""
    for k in MODEL_KEYS:
        monkeypatch.delenv(k, raising=False)


@pytest.fixture
def server():
    """A fake OpenAI-compatible server for the test (its ``url``, the requests it saw)."""
    with fake.FakeOpenAIServer(lifetime_s=300) as srv:
        yield srv
