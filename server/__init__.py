"""The Driving Arena service: REST API, web pages, database, leaderboard and admin CLI."""
