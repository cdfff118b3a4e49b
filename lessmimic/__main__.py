from lessmimic.cli import run

run()
