// SIGINT and SIGTERM end catgs-client cleanly: streams half-close, retries stop, reports are
// still printed.
#pragma once

#include <atomic>

namespace catgs::client {

/// True once a signal asked the client to stop.
const std::atomic<bool>& stop_requested();

/// Installs the handlers that set stop_requested().
void stop_on_signals();

}  // namespace catgs::client
