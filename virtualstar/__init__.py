"""VirtualStar: astronomy, the VirtualStar Server, the recorder, the panel and the `vs` CLI."""
