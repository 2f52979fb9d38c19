"""Analytics (IAnalyse / INavigableAnalyse) and the built-in ones."""
