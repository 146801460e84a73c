"""Which pixels a fit uses: samples near the predicted shadow boundary on every kind of receiver."""
