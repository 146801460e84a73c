"""Reading photos, their times, cameras, suns and groups."""
