"""Stage package ``synthesize`` of the refine data flow (see DEVELOPERS.md)."""
