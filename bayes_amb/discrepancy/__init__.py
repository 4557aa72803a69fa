"""Model discrepancy: locate where the nominal model fails, name the missing physics, model
it and show the fit improve."""
