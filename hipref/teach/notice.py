"""What a participant's page says when it loses its learner: the server stopped, or the page's kernel died.

A page served by Voila keeps showing its buttons after either; clicks then reach nothing and the page says
nothing. `connection_watch` is a cell output whose script asks the server for the page's kernel every
POLL_SECONDS and, when the server does not answer or no longer knows the kernel, covers the page with a
notice: every answer given is saved (each is written before the learner is told), and how to go on. Once the
participant's closing screen is on the page (`FINISHED_CLASS`) it stops asking: nothing is left to lose, and
the experimenter stopping the server then is the session's normal end.

A killed kernel is not restarted in place (`hipref.teach.server.voila_command`): a restarted kernel has
none of the page's widgets, so the page would stay dead while the server reports the kernel alive. Removed,
it is reported unknown, and reloading the page starts a kernel that resumes the session from its files.
"""

from __future__ import annotations

import json

from IPython.display import HTML

POLL_SECONDS = 3.0
"""How often the page asks the server whether its kernel is still there."""

SERVER_STOPPED = (
    "The teaching server has stopped. Every answer you gave is saved. Please tell the experimenter; once the "
    "server runs again, reload this page to go on where you stopped."
)
"""The notice when the server does not answer."""

KERNEL_GONE = (
    "This page has lost its connection to the robot's learner. Every answer you gave is saved. Reload this "
    "page to go on where you stopped."
)
"""The notice when the server answers but no longer knows the page's kernel (it died, or was shut down)."""

NOTICE_CLASS = "hipref-connection-notice"
"""The notice's element (hidden until needed)."""

FINISHED_CLASS = "hipref-finished"
"""The class of a participant's closing screen: once it is on the page the script stops asking, as nothing is
left to lose or to go on with (the experimenter stopping the server then is the session's normal end)."""

_PAGE = """
<div class="{notice}" role="alert" style="display: none; position: fixed; inset: 0; z-index: 10000;
  background: rgba(255, 255, 255, 0.9); align-items: center; justify-content: center;">
  <div style="max-width: 36em; padding: 2em; border: 2px solid #b00020; border-radius: 8px;
    background: white; font-size: 1.3em; line-height: 1.5;"></div>
</div>
<script>
(function () {{
  const notices = document.getElementsByClassName({notice_json});
  const notice = notices[notices.length - 1];
  const config = JSON.parse(document.getElementById("jupyter-config-data").textContent);
  const url = (config.baseUrl || "/") + "api/kernels/" + config.kernelId;
  function show(text) {{
    notice.firstElementChild.textContent = text;
    notice.style.display = "flex";
  }}
  async function check() {{
    if (document.getElementsByClassName({finished_json}).length) return;  // all answered: nothing to say
    let reply;
    try {{
      reply = await fetch(url, {{ cache: "no-store" }});
    }} catch (error) {{
      show({server_stopped});  // no answer: keep asking, the server may come back
      setTimeout(check, {every_ms});
      return;
    }}
    if (reply.status === 404) {{
      show({kernel_gone});  // final for this page: only a reload gives it a kernel again
      return;
    }}
    notice.style.display = "none";
    setTimeout(check, {every_ms});
  }}
  setTimeout(check, {every_ms});
}})();
</script>
"""


def connection_watch() -> HTML:
    """The hidden notice and its script (module docstring), displayed by a cell of the participant's view."""
    return HTML(
        _PAGE.format(
            notice=NOTICE_CLASS,
            notice_json=json.dumps(NOTICE_CLASS),
            finished_json=json.dumps(FINISHED_CLASS),
            server_stopped=json.dumps(SERVER_STOPPED),
            kernel_gone=json.dumps(KERNEL_GONE),
            every_ms=round(POLL_SECONDS * 1000),
        )
    )
