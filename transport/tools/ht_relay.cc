// ht_relay: a UDP impairment relay (delay, jitter, loss, bursty loss, reordering, duplication,
// rate limit) between the operator station (client) and the remote node (server), for tests and
// `deploy/run-loopback --impair SPEC` where tc netem is not available.

#include <sys/prctl.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <exception>
#include <string>

#include "transport/command_line.h"
#include "transport/impairment.h"

namespace {
std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) { g_stop.store(true); }

constexpr const char* kSpecHelp = R"(SPEC (for --impair, --impair-up, --impair-down):
  Comma-separated key=value, any order, e.g.
    delay=50ms,jitter=10ms,loss=5%,burst=4,reorder=2%,dup=1%,rate=20mbit,seed=7
  'none' or empty = no impairment.
  delay=T        one-way base delay.
  jitter=T       per-packet uniform in [-J, +J] added to delay, clipped at 0 (jitter alone can
                 reorder, as netem does).
                 Time units: us, ms, s (a bare number is ms).
  loss=P%        (or a fraction 0..1): random loss.
  burst=B        mean burst length in packets (>= 1): Gilbert-Elliott two-state model, loss 100%
                 in Bad and 0% in Good, p(Good->Bad) = P*r/(1-P), r = p(Bad->Good) = 1/B, so the
                 long-run loss rate is P and the mean burst length B. P >= 100% is rejected with
                 burst (and so is P > B/(B+1), where p(Good->Bad) would exceed 1).
  reorder=P%     that fraction of packets is held an extra reorder-gap=T (default 5ms) so later
                 packets overtake it.
  dup=P%         that fraction is delivered twice (the copy right after the original).
  rate=R         link rate, units bit, kbit, mbit, gbit (bits per second; bare number = bit/s);
                 packets are serialised (tx start = max(arrival, link free); link busy size*8/R)
                 before the delay; queue limit limit=N packets (default 1000), tail drop beyond
                 it.
  seed=N         (default 1).
  Per packet: loss, then the rate queue, then serialisation, delay + jitter, reorder hold, dup.

Directions: up = client -> server (--listen side to --forward), down = server -> client.
--impair applies to both (down uses seed+1 so the directions are independent); --impair-up and
--impair-down override one direction each.

Statistics (--stats): {"spec": {"up": ..., "down": ...}, "up": {...}, "down": {...}}; each
direction has the counters received, dropped_loss, dropped_queue, dropped_oversize, duplicated,
reordered, forwarded (datagrams actually sent, copies included), send_errors, bytes_in,
bytes_out, in_flight_at_exit, then the same per message type (tool_state, contact_model, ...,
"other" for datagrams of neither this protocol version's header nor the older one's).)";

ht::ImpairmentSpec ParseSpecOption(const std::string& option, const std::string& text) {
  try {
    return ht::ImpairmentSpec::Parse(text);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(option + ": " + e.what());
  }
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "ht_relay: UDP impairment relay between the operator station (client) and the remote\n"
      "node (server). Datagrams from clients on --listen go to --forward from a second socket;\n"
      "datagrams from --forward on that socket go back to the last client. Each direction is\n"
      "impaired by a seeded, deterministic model (see SPEC below). Stops on SIGINT/SIGTERM\n"
      "(exit 0 after writing the statistics) or after --duration."};
  app.footer(kSpecHelp);
  std::string listen, forward, impair, impair_up, impair_down, stats_file, port_file;
  double duration_s = 0.0;
  bool quiet = false;
  app.add_option("--listen", listen, "client-side UDP address HOST:PORT (port 0 = any free)")
      ->required();
  app.add_option("--forward", forward, "server UDP address HOST:PORT")->required();
  CLI::Option* impair_opt =
      app.add_option("--impair", impair, "SPEC for both directions (down with seed+1)");
  CLI::Option* impair_up_opt =
      app.add_option("--impair-up", impair_up, "SPEC client -> server (overrides --impair)");
  CLI::Option* impair_down_opt =
      app.add_option("--impair-down", impair_down, "SPEC server -> client (overrides --impair)");
  app.add_option("--stats", stats_file, "write statistics JSON here every second and at exit");
  app.add_option("--port-file", port_file, "write the bound listen port to this file");
  app.add_option("--duration", duration_s, "stop after this many seconds (0 = until a signal)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_flag("--quiet", quiet, "no progress lines");
  bool check_only = false;
  app.add_flag("--check", check_only,
               "check the addresses and SPECs, say what is wrong, and exit without relaying "
               "(status 0 when all is well)");
  if (const auto rc = ht::ParseCommandLine(app, argc, argv, "ht_relay")) return *rc;

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  // Departures are timed by ppoll; a 1 us timer slack (default 50 us) keeps them on time.
  ::prctl(PR_SET_TIMERSLACK, 1000UL, 0UL, 0UL, 0UL);
  try {
    ht::RelayConfig config;
    config.listen_address = ht::SocketAddress::Parse(listen);
    config.forward_address = ht::SocketAddress::Parse(forward);
    if (config.forward_address.port() == 0) {
      throw std::invalid_argument("--forward '" + forward + "': port must be 1..65535");
    }
    if (impair_opt->count() > 0) {
      config.up = ParseSpecOption("--impair", impair);
      config.down = config.up;
      config.down.seed = config.up.seed + 1;
    }
    if (impair_up_opt->count() > 0) config.up = ParseSpecOption("--impair-up", impair_up);
    if (impair_down_opt->count() > 0) config.down = ParseSpecOption("--impair-down", impair_down);
    if (check_only) return 0;
    config.port_file = port_file;
    config.stats_file = stats_file;
    config.duration_s = duration_s;
    config.progress_period_s = quiet ? 0.0 : 1.0;
    ht::ImpairmentRelay relay(config);
    relay.Run(g_stop);
    const ht::TrafficCounters up = relay.up_stats().Total();
    const ht::TrafficCounters down = relay.down_stats().Total();
    std::printf("[relay] done: up %llu in, %llu out; down %llu in, %llu out\n",
                static_cast<unsigned long long>(up.received),
                static_cast<unsigned long long>(up.forwarded),
                static_cast<unsigned long long>(down.received),
                static_cast<unsigned long long>(down.forwarded));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ht_relay: error: %s\n", e.what());
    return 2;
  }
}
