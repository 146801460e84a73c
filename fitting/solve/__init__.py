"""One time of day: the pixel model, optimistix least squares, errors, levels of detail, options."""
