def main():
    raise SystemExit("lessmimic: CLI not built yet")
