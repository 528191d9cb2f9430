"""The browser console: a style mixer with the character drawn live, served beside the frame loop.

server.py   the web server (aiohttp) in its own process: the page, its files, one WebSocket a page
messages.py what a page may send, validated in one place
link.py     the frame loop's side: the page as a control source (poll) and as an output (frames)
presets.py  writing presets to a file the CLI reads
static/     the page's own HTML, JavaScript and CSS (nothing fetched from elsewhere)
"""
