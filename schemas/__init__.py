from pydantic import BaseModel, ConfigDict


class Strict(BaseModel):
    """A typed hand-over that refuses fields it does not declare (pydantic ``extra="forbid"``)."""

    model_config = ConfigDict(extra="forbid")


class Frozen(Strict):
    """A :class:`Strict` model whose instances cannot be changed once made (pydantic ``frozen=True``)."""

    model_config = ConfigDict(frozen=True)
