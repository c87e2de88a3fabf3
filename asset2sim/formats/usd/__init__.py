"""OpenUSD: one stage opened under the reader's trust rules (:mod:`.stage`), the reader (:mod:`.reader`), the
export of an output folder with UsdPhysics (:mod:`.export`) and the one physics writer (:mod:`.physics`)."""
