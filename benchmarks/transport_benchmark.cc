// Cost of the transport per datagram: sealing (encode + HMAC-SHA-256-128) and opening (header,
// replay window, MAC, body decode) tool states and full contact models, the MAC alone, and one
// loopback round trip of a sealed datagram against a raw one (the latency the transport adds).
// Not run by ctest: speed is reported, never asserted.
#include <benchmark/benchmark.h>

#include <thread>

#include "transport/link.h"
#include "transport/messages.h"

namespace ht {
namespace {

const MacKey& Key() {
  static const MacKey key = MacKey::Generate();
  return key;
}

wire::ContactModelMessage FullModel() {
  wire::ContactModelMessage m;
  m.model.num_contacts = wire::kMaxWireContacts;
  for (int i = 0; i < wire::kMaxWireContacts; ++i) {
    m.model.contacts[i].depth_m = 1e-4;
    m.model.contacts[i].gradient = {{0, 0, -1}, {0.001, 0, 0}};
    m.model.contacts[i].stiffness_n_per_m = 8000;
    m.model.contacts[i].normal_W = {0, 0, 1};
  }
  return m;
}

/// One MAC of `Bytes` bytes over a message of state.range(0) bytes, by `compute`.
template <std::size_t Bytes, typename Compute>
void MacLoop(benchmark::State& state, Compute&& compute) {
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(state.range(0)), 0x5a);
  std::array<std::uint8_t, Bytes> mac{};
  for (auto _ : state) {
    compute(bytes, Key(), mac);
    benchmark::DoNotOptimize(mac);
  }
  state.SetBytesProcessed(state.iterations() * state.range(0));
}

void BM_ComputeMac(benchmark::State& state) {
  MacLoop<wire::kMacBytes>(state, [](auto& m, auto& k, auto& mac) { ComputeMac(m, k, mac); });
}
// 50 B: a compact tool state's header + body; 122 B: the f64 one's; 1400 B: a contact model with 14
// contacts.
BENCHMARK(BM_ComputeMac)->Arg(50)->Arg(122)->Arg(1400);

/// The MAC of protocol versions 2 to 7 (crypto_auth, HMAC-SHA-512-256, all 32 bytes), for the
/// comparison; a version-8 node computes it only to answer an older operator's Hello.
void BM_ComputeFullMacOfVersion7(benchmark::State& state) {
  MacLoop<wire::kFullMacBytes>(state,
                               [](auto& m, auto& k, auto& mac) { ComputeFullMac(m, k, mac); });
}
// The same messages in version 7's layout (10 header bytes more).
BENCHMARK(BM_ComputeFullMacOfVersion7)->Arg(60)->Arg(132)->Arg(1410);

void BM_SealToolState(benchmark::State& state) {
  wire::ToolStateMessage m;
  wire::Header h{wire::MessageType::kToolState, 7, 1, 0};
  for (auto _ : state) {
    ++h.sequence;
    benchmark::DoNotOptimize(wire::EncodeToolState(h, m, Key()));
  }
}
BENCHMARK(BM_SealToolState);

void BM_SealContactModel14(benchmark::State& state) {
  const wire::ContactModelMessage m = FullModel();
  wire::Header h{wire::MessageType::kContactModel, 7, 1, 0};
  for (auto _ : state) {
    ++h.sequence;
    benchmark::DoNotOptimize(wire::EncodeContactModel(h, m, Key()));
  }
}
BENCHMARK(BM_SealContactModel14);

/// Opening through a SecureLink (header, session, replay window, MAC) and decoding the body.
template <typename Encode, typename Decode>
void OpenLoop(benchmark::State& state, LinkRole role, wire::MessageType type, Encode&& encode,
              Decode&& decode) {
  UdpSocket socket(SocketAddress::Parse("127.0.0.1:0"));
  SecureLink link(socket, Key(), role);
  std::vector<wire::Datagram> datagrams(4096);
  for (std::size_t i = 0; i < datagrams.size(); ++i)
    datagrams[i] = encode(wire::Header{type, 7, i + 1, 0});
  std::size_t i = 0;
  for (auto _ : state) {
    if (i == datagrams.size()) {  // a new session, so that the same sequence numbers are fresh
      state.PauseTiming();
      link.ResetSession();
      i = 0;
      state.ResumeTiming();
    }
    wire::Header h;
    std::span<const std::uint8_t> body;
    bool late = false;
    const bool ok = link.Open(datagrams[i++].view(), 7, h, body, late) == wire::DecodeStatus::kOk;
    benchmark::DoNotOptimize(ok ? decode(body) : decltype(decode(body)){});
  }
}

void BM_OpenToolState(benchmark::State& state) {
  OpenLoop(
      state, LinkRole::kRemote, wire::MessageType::kToolState,
      [](const wire::Header& h) { return wire::EncodeToolState(h, {}, Key()); },
      [](std::span<const std::uint8_t> b) {
        wire::ToolStateMessage m;
        return wire::DecodeToolState(b, m);
      });
}
BENCHMARK(BM_OpenToolState);

void BM_OpenContactModel14(benchmark::State& state) {
  static const wire::ContactModelMessage model = FullModel();
  OpenLoop(
      state, LinkRole::kOperator, wire::MessageType::kContactModel,
      [](const wire::Header& h) { return wire::EncodeContactModel(h, model, Key()); },
      [](std::span<const std::uint8_t> b) {
        wire::ContactModelMessage m;
        return wire::DecodeContactModel(b, m);
      });
}
BENCHMARK(BM_OpenContactModel14);

void BM_RejectForgedToolState(benchmark::State& state) {
  // What a flood of well-formed forgeries costs the receiver: header checks plus one HMAC each.
  MacKey wrong = MacKey::Generate();
  OpenLoop(
      state, LinkRole::kRemote, wire::MessageType::kToolState,
      [&](const wire::Header& h) { return wire::EncodeToolState(h, {}, wrong); },
      [](std::span<const std::uint8_t> b) { return b.size(); });
}
BENCHMARK(BM_RejectForgedToolState);

/// One round trip on 127.0.0.1 through an echo thread: raw (the bytes as they are) or sealed
/// (the echo side opens and decodes a tool state, then seals and sends a contact model back; the
/// first side opens and decodes that). The difference is the latency the transport adds.
void RoundTrip(benchmark::State& state, bool sealed) {
  UdpSocket a(SocketAddress::Parse("127.0.0.1:0")), b(SocketAddress::Parse("127.0.0.1:0"));
  const SocketAddress to_b = b.local_address(), to_a = a.local_address();
  SecureLink la(a, Key(), LinkRole::kOperator), lb(b, Key(), LinkRole::kRemote);
  std::atomic<bool> stop{false};
  std::thread echo([&] {
    std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buf{};
    const wire::ContactModelMessage model = FullModel();
    while (!stop.load(std::memory_order_relaxed)) {
      SocketAddress from;
      auto n = b.ReceiveFrom(buf, from);
      if (!n) continue;  // busy-poll: measures the transport, not the scheduler
      if (!sealed) {
        b.SendTo({buf.data(), *n}, to_a);
        continue;
      }
      wire::Header h;
      std::span<const std::uint8_t> body;
      bool late = false;
      wire::ToolStateMessage m;
      if (lb.Open({buf.data(), *n}, 7, h, body, late) == wire::DecodeStatus::kOk &&
          wire::DecodeToolState(body, m) == wire::DecodeStatus::kOk) {
        lb.Send(wire::EncodeContactModel(lb.NextHeader(wire::MessageType::kContactModel, 7), model,
                                         Key()),
                to_a);
      }
    }
  });
  std::array<std::uint8_t, wire::kMaxDatagramBytes + 1> buf{};
  const wire::Datagram raw_request = wire::EncodeToolState({}, {}, Key());
  for (auto _ : state) {
    if (sealed) {
      la.Send(wire::EncodeToolState(la.NextHeader(wire::MessageType::kToolState, 7), {}, Key()),
              to_b);
    } else {
      a.SendTo(raw_request.view(), to_b);
    }
    SocketAddress from;
    std::optional<std::size_t> n;
    while (!(n = a.ReceiveFrom(buf, from))) {
    }
    if (sealed) {
      wire::Header h;
      std::span<const std::uint8_t> body;
      bool late = false;
      wire::ContactModelMessage m;
      if (la.Open({buf.data(), *n}, 7, h, body, late) != wire::DecodeStatus::kOk ||
          wire::DecodeContactModel(body, m) != wire::DecodeStatus::kOk) {
        state.SkipWithError("round trip failed to open");
      }
    }
  }
  stop = true;
  echo.join();
}
void BM_LoopbackRoundTripRaw(benchmark::State& state) { RoundTrip(state, false); }
void BM_LoopbackRoundTripSealed(benchmark::State& state) { RoundTrip(state, true); }
BENCHMARK(BM_LoopbackRoundTripRaw)->UseRealTime();
BENCHMARK(BM_LoopbackRoundTripSealed)->UseRealTime();

}  // namespace
}  // namespace ht

BENCHMARK_MAIN();
