"""Stage package ``ingest`` of the refine data flow (see DEVELOPERS.md)."""
