// The impairment relay: spec parsing, the seeded model's statistics against the closed-form
// values of each impairment, and ht_relay as a real process between two UDP sockets.

#include "transport/impairment.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "transport/auth.h"
#include "transport/messages.h"
#include "transport/udp_socket.h"

extern char** environ;

namespace ht {
namespace {

constexpr std::int64_t kMs = 1'000'000;  // ns
constexpr std::int64_t kUs = 1'000;      // ns

// ---------------------------------------------------------------------------------------------
// Spec parsing.

TEST(ImpairmentSpecParse, NoneAndEmptyMeanNoImpairment) {
  for (const char* text : {"", "none", "  none "}) {
    const ImpairmentSpec s = ImpairmentSpec::Parse(text);
    EXPECT_TRUE(s.IsNone()) << text;
    EXPECT_EQ(s, ImpairmentSpec{}) << text;
    EXPECT_EQ(s.ToString(), "none");
  }
}

TEST(ImpairmentSpecParse, ReadsEveryKeyInAnyOrder) {
  const ImpairmentSpec s = ImpairmentSpec::Parse(
      "seed=7, rate=20mbit,dup=1%,reorder=2%,burst=4,loss=5%,jitter=10ms,delay=50ms,"
      "reorder-gap=3ms,limit=50");
  EXPECT_EQ(s.delay_ns, 50 * kMs);
  EXPECT_EQ(s.jitter_ns, 10 * kMs);
  EXPECT_DOUBLE_EQ(s.loss, 0.05);
  EXPECT_DOUBLE_EQ(s.burst_packets, 4.0);
  EXPECT_DOUBLE_EQ(s.reorder, 0.02);
  EXPECT_EQ(s.reorder_gap_ns, 3 * kMs);
  EXPECT_DOUBLE_EQ(s.dup, 0.01);
  EXPECT_DOUBLE_EQ(s.rate_bps, 20e6);
  EXPECT_EQ(s.limit_packets, 50u);
  EXPECT_EQ(s.seed, 7u);
  EXPECT_FALSE(s.IsNone());
}

TEST(ImpairmentSpecParse, DefaultsAreFiveMsGapThousandPacketsSeedOne) {
  const ImpairmentSpec s = ImpairmentSpec::Parse("reorder=1%");
  EXPECT_EQ(s.reorder_gap_ns, 5 * kMs);
  EXPECT_EQ(s.limit_packets, 1000u);
  EXPECT_EQ(s.seed, 1u);
}

TEST(ImpairmentSpecParse, TimeUnitsAreUsMsSAndBareMs) {
  EXPECT_EQ(ImpairmentSpec::Parse("delay=250us").delay_ns, 250 * kUs);
  EXPECT_EQ(ImpairmentSpec::Parse("delay=3ms").delay_ns, 3 * kMs);
  EXPECT_EQ(ImpairmentSpec::Parse("delay=2s").delay_ns, 2000 * kMs);
  EXPECT_EQ(ImpairmentSpec::Parse("delay=7").delay_ns, 7 * kMs);
  EXPECT_EQ(ImpairmentSpec::Parse("delay=1.5ms").delay_ns, 1500 * kUs);
  EXPECT_EQ(ImpairmentSpec::Parse("jitter=0.25s").jitter_ns, 250 * kMs);
  EXPECT_EQ(ImpairmentSpec::Parse("reorder-gap=800us").reorder_gap_ns, 800 * kUs);
}

TEST(ImpairmentSpecParse, FractionsArePercentOrZeroToOne) {
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("loss=5%").loss, 0.05);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("loss=0.05").loss, 0.05);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("loss=100%").loss, 1.0);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("dup=0.5").dup, 0.5);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("reorder=12.5%").reorder, 0.125);
}

TEST(ImpairmentSpecParse, RateUnitsAreBitsPerSecond) {
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("rate=1500").rate_bps, 1500.0);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("rate=100bit").rate_bps, 100.0);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("rate=64kbit").rate_bps, 64e3);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("rate=20mbit").rate_bps, 20e6);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("rate=1.5gbit").rate_bps, 1.5e9);
  EXPECT_DOUBLE_EQ(ImpairmentSpec::Parse("rate=10Mbit").rate_bps, 10e6);
}

TEST(ImpairmentSpecParse, ToStringIsCanonicalAndParsesBack) {
  EXPECT_EQ(ImpairmentSpec::Parse("seed=7,rate=20mbit,dup=1%,reorder=2%,burst=4,loss=5%,"
                                  "jitter=10ms,delay=50ms")
                .ToString(),
            "delay=50ms,jitter=10ms,loss=5%,burst=4,reorder=2%,dup=1%,rate=20mbit,seed=7");
  for (const char* text :
       {"delay=50ms,jitter=10ms,loss=5%,burst=4,reorder=2%,dup=1%,rate=20mbit,seed=7",
        "delay=1.2345us", "delay=2s,jitter=3us", "loss=0.123456789", "loss=1%,burst=2.5",
        "reorder=3%,reorder-gap=2ms", "rate=1234567bit,limit=17", "rate=0.5", "dup=100%",
        "delay=1ms,seed=18446744073709551615"}) {
    const ImpairmentSpec s = ImpairmentSpec::Parse(text);
    EXPECT_EQ(ImpairmentSpec::Parse(s.ToString()), s) << text << " -> " << s.ToString();
  }
}

// The message of a rejected spec, or "" when it was accepted.
std::string ParseError(const std::string& text) {
  try {
    ImpairmentSpec::Parse(text);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ImpairmentSpecParse, RejectsBadTextNamingKeyValueAndForm) {
  struct Case {
    const char* text;
    const char* key;       // must appear in the message
    const char* bad_text;  // must appear in the message
  };
  const Case cases[] = {
      {"delay=abc", "delay", "abc"},
      {"delay=5xs", "delay", "5xs"},
      {"delay=-5ms", "delay", "-5ms"},
      {"jitter=1h", "jitter", "1h"},
      {"reorder-gap=x", "reorder-gap", "x"},
      {"loss=150%", "loss", "150%"},
      {"loss=1.5", "loss", "1.5"},
      {"loss=5x", "loss", "5x"},
      {"loss=nan", "loss", "nan"},
      {"dup=-1%", "dup", "-1%"},
      {"reorder=2", "reorder", "2"},
      {"burst=0.5", "burst", "0.5"},
      {"burst=4pk", "burst", "4pk"},
      {"rate=5mbps", "rate", "5mbps"},
      {"rate=0", "rate", "0"},
      {"rate=-1mbit", "rate", "-1mbit"},
      {"limit=0", "limit", "0"},
      {"limit=2.5", "limit", "2.5"},
      {"limit=9999999", "limit", "9999999"},
      {"seed=-1", "seed", "-1"},
      {"seed=abc", "seed", "abc"},
      {"speed=5", "speed", "speed=5"},
      {"delay", "delay", "delay"},
      {"delay=5ms,delay=6ms", "delay", "twice"},
      {"none,delay=5ms", "none", "none"},
      {"delay=5ms,", "", "must be key=value"},
      {"delay=", "delay", "not a number"},
  };
  for (const Case& c : cases) {
    const std::string message = ParseError(c.text);
    ASSERT_FALSE(message.empty()) << c.text << " was accepted";
    EXPECT_NE(message.find(c.key), std::string::npos) << c.text << ": " << message;
    EXPECT_NE(message.find(c.bad_text), std::string::npos) << c.text << ": " << message;
  }
  // The accepted form is named.
  EXPECT_NE(ParseError("delay=5xs").find("us, ms, s"), std::string::npos);
  EXPECT_NE(ParseError("rate=5mbps").find("bit, kbit, mbit, gbit"), std::string::npos);
  EXPECT_NE(ParseError("speed=5").find("delay, jitter, loss"), std::string::npos);
}

TEST(ImpairmentSpecParse, BurstRejectsTotalLossAndImpossibleChains) {
  const std::string total = ParseError("loss=100%,burst=4");
  EXPECT_NE(total.find("loss"), std::string::npos) << total;
  EXPECT_NE(total.find("burst"), std::string::npos) << total;
  // p(Good→Bad) = P·r/(1 − P) > 1 for P = 60 %, B = 1 (needs P <= B/(B+1) = 50 %).
  const std::string impossible = ParseError("loss=60%,burst=1");
  EXPECT_NE(impossible.find("burst"), std::string::npos) << impossible;
  EXPECT_TRUE(ParseError("loss=50%,burst=1").empty());
  EXPECT_TRUE(ParseError("loss=100%").empty());  // without burst: drop everything
}

// ---------------------------------------------------------------------------------------------
// The model.

struct Tally {
  std::size_t packets = 0, lost = 0, queue_dropped = 0, delivered = 0, duplicated = 0,
              reordered = 0;
  std::vector<std::size_t> loss_bursts;  // lengths of runs of consecutive losses
};

// Feeds `n` packets of `size` bytes, one every `period_ns`, and tallies the decisions.
Tally Feed(ImpairmentModel& model, std::size_t n, std::int64_t period_ns, std::size_t size) {
  Tally t;
  std::size_t run = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const PacketDecision d = model.Decide(static_cast<std::int64_t>(i) * period_ns, size);
    ++t.packets;
    if (d.fate == PacketFate::kDroppedLoss) {
      ++t.lost;
      ++run;
      continue;
    }
    if (run > 0) t.loss_bursts.push_back(run);
    run = 0;
    if (d.fate == PacketFate::kDroppedQueue) {
      ++t.queue_dropped;
      continue;
    }
    ++t.delivered;
    if (d.copies == 2) ++t.duplicated;
    if (d.reordered) ++t.reordered;
  }
  if (run > 0) t.loss_bursts.push_back(run);
  return t;
}

double Mean(const std::vector<std::size_t>& v) {
  double sum = 0.0;
  for (std::size_t x : v) sum += static_cast<double>(x);
  return sum / static_cast<double>(v.size());
}

double Ratio(std::size_t a, std::size_t b) {
  return static_cast<double>(a) / static_cast<double>(b);
}

// Binomial standard error of a fraction p over n trials.
double BinomialSigma(double p, std::size_t n) {
  return std::sqrt(p * (1.0 - p) / static_cast<double>(n));
}

constexpr std::size_t kPackets = 200'000;

TEST(ImpairmentModel, RandomLossRateIsWithinThreeSigmaOfP) {
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    ImpairmentSpec spec;
    spec.loss = 0.05;
    spec.seed = seed;
    ImpairmentModel model(spec);
    const Tally t = Feed(model, kPackets, kMs, 100);
    const double rate = static_cast<double>(t.lost) / kPackets;
    EXPECT_NEAR(rate, 0.05, 3 * BinomialSigma(0.05, kPackets)) << "seed " << seed;
    // Independent losses: runs are geometric with mean 1/(1 − P).
    EXPECT_NEAR(Mean(t.loss_bursts), 1.0 / 0.95, 0.02) << "seed " << seed;
  }
}

TEST(ImpairmentModel, TotalLossDropsEverything) {
  ImpairmentModel model(ImpairmentSpec::Parse("loss=100%"));
  EXPECT_EQ(Feed(model, 1000, kMs, 100).lost, 1000u);
}

TEST(ImpairmentModel, GilbertElliottGivesLossRatePAndMeanBurstB) {
  for (const double burst : {1.0, 4.0, 10.0}) {
    const double p_loss = 0.05;
    ImpairmentSpec spec;
    spec.loss = p_loss;
    spec.burst_packets = burst;
    spec.seed = 11;
    ImpairmentModel model(spec);
    const Tally t = Feed(model, kPackets, kMs, 100);
    // Loss count of a two-state Markov chain: variance n·π(1 − π)·(1 + λ)/(1 − λ), with the
    // chain's second eigenvalue λ = 1 − p(G→B) − p(B→G).
    const double r = 1.0 / burst;
    const double p_gb = p_loss * r / (1.0 - p_loss);
    const double lambda = 1.0 - p_gb - r;
    const double sigma = BinomialSigma(p_loss, kPackets) * std::sqrt((1 + lambda) / (1 - lambda));
    EXPECT_NEAR(static_cast<double>(t.lost) / kPackets, p_loss, 3 * sigma) << "burst " << burst;
    // Bad runs are geometric with mean B and variance B(B − 1).
    const double burst_se =
        std::sqrt(burst * (burst - 1.0) / static_cast<double>(t.loss_bursts.size()));
    EXPECT_NEAR(Mean(t.loss_bursts), burst, std::max(3 * burst_se, 1e-9)) << "burst " << burst;
  }
}

TEST(ImpairmentModel, BurstLossLossFollowsLossWithProbabilityOneMinusR) {
  // A second route to the burst length: P(loss | previous lost) = 1 − 1/B.
  ImpairmentModel model(ImpairmentSpec::Parse("loss=10%,burst=5,seed=4"));
  std::size_t after_loss = 0, loss_after_loss = 0;
  bool previous_lost = false;
  for (std::size_t i = 0; i < kPackets; ++i) {
    const bool lost =
        model.Decide(static_cast<std::int64_t>(i) * kMs, 64).fate == PacketFate::kDroppedLoss;
    if (previous_lost) {
      ++after_loss;
      if (lost) ++loss_after_loss;
    }
    previous_lost = lost;
  }
  const double conditional = Ratio(loss_after_loss, after_loss);
  EXPECT_NEAR(conditional, 0.8, 3 * BinomialSigma(0.8, after_loss));
}

TEST(ImpairmentModel, DuplicateAndReorderFractionsMatchSpec) {
  ImpairmentModel model(ImpairmentSpec::Parse("dup=3%,reorder=7%,loss=2%,seed=5"));
  const Tally t = Feed(model, kPackets, kMs, 100);
  EXPECT_NEAR(Ratio(t.duplicated, t.delivered), 0.03, 3 * BinomialSigma(0.03, t.delivered));
  EXPECT_NEAR(Ratio(t.reordered, t.delivered), 0.07, 3 * BinomialSigma(0.07, t.delivered));
}

TEST(ImpairmentModel, ReorderedPacketsAreHeldTheGapAndOvertaken) {
  ImpairmentModel model(ImpairmentSpec::Parse("delay=10ms,reorder=10%,reorder-gap=3ms,seed=9"));
  std::int64_t latest_delivery = 0;
  std::size_t overtaken = 0, reordered = 0;
  for (std::int64_t i = 0; i < 10'000; ++i) {
    const std::int64_t arrival = i * kMs;
    const PacketDecision d = model.Decide(arrival, 100);
    ASSERT_EQ(d.fate, PacketFate::kDelivered);
    EXPECT_EQ(d.deliver_ns, arrival + 10 * kMs + (d.reordered ? 3 * kMs : 0));
    if (d.reordered) ++reordered;
    // A packet delivered before an earlier one has overtaken it; the earlier one was held.
    if (d.deliver_ns < latest_delivery) ++overtaken;
    latest_delivery = std::max(latest_delivery, d.deliver_ns);
  }
  EXPECT_GT(reordered, 0u);
  EXPECT_GT(overtaken, 0u);
}

TEST(ImpairmentModel, DelayPlusJitterStaysWithinBoundsAndIsUniform) {
  const std::int64_t delay = 20 * kMs, jitter = 5 * kMs;
  ImpairmentModel model(ImpairmentSpec::Parse("delay=20ms,jitter=5ms,seed=3"));
  double sum = 0.0;
  std::int64_t lo = INT64_MAX, hi = INT64_MIN;
  std::size_t inversions = 0;
  std::int64_t previous = 0;
  for (std::int64_t i = 0; i < static_cast<std::int64_t>(kPackets); ++i) {
    const std::int64_t arrival = i * kMs;
    const PacketDecision d = model.Decide(arrival, 100);
    ASSERT_EQ(d.copies, 1);
    const std::int64_t latency = d.deliver_ns - arrival;
    ASSERT_GE(latency, delay - jitter);
    ASSERT_LE(latency, delay + jitter);
    sum += static_cast<double>(latency);
    lo = std::min(lo, latency);
    hi = std::max(hi, latency);
    if (d.deliver_ns < previous) ++inversions;
    previous = d.deliver_ns;
  }
  // Uniform on [d − J, d + J]: mean d, standard deviation J/√3.
  const double se = static_cast<double>(jitter) / std::sqrt(3.0 * kPackets);
  EXPECT_NEAR(sum / kPackets, static_cast<double>(delay), 3 * se);
  EXPECT_LT(lo, delay - jitter + jitter / 100);  // reaches both ends
  EXPECT_GT(hi, delay + jitter - jitter / 100);
  EXPECT_GT(inversions, 0u);  // jitter larger than the packet spacing reorders, as in netem
}

TEST(ImpairmentModel, JitterLargerThanDelayIsClippedAtZero) {
  // delay 1 ms, jitter 5 ms: P(delay + j <= 0) = (J − D + 1)/(2J + 1) over integer ns ≈ 0.4.
  ImpairmentModel model(ImpairmentSpec::Parse("delay=1ms,jitter=5ms,seed=8"));
  std::size_t at_zero = 0;
  for (std::int64_t i = 0; i < static_cast<std::int64_t>(kPackets); ++i) {
    const PacketDecision d = model.Decide(i * kMs, 100);
    ASSERT_GE(d.deliver_ns, i * kMs);
    if (d.deliver_ns == i * kMs) ++at_zero;
  }
  EXPECT_NEAR(static_cast<double>(at_zero) / kPackets, 0.4, 3 * BinomialSigma(0.4, kPackets));
}

TEST(ImpairmentModel, RateSpacesBackToBackPacketsBySizeTimesEightOverRate) {
  // 1000 bytes at 20 Mbit/s: 8000 bit / 2e7 bit/s = 400 us on the link per packet.
  ImpairmentModel model(ImpairmentSpec::Parse("rate=20mbit,delay=10ms"));
  std::int64_t previous = 0;
  for (int i = 0; i < 200; ++i) {
    const std::int64_t arrival = i * kUs;  // far faster than the link
    const PacketDecision d = model.Decide(arrival, 1000);
    ASSERT_EQ(d.fate, PacketFate::kDelivered);
    if (i == 0) {
      EXPECT_EQ(d.deliver_ns, 400 * kUs + 10 * kMs);  // serialised, then delayed
    } else {
      EXPECT_EQ(d.deliver_ns - previous, 400 * kUs) << i;
    }
    previous = d.deliver_ns;
  }
  // A rate that does not divide: 100 bytes at 3 Mbit/s = 266 666.67 ns per packet.
  ImpairmentModel odd(ImpairmentSpec::Parse("rate=3mbit"));
  const std::int64_t first = odd.Decide(0, 100).deliver_ns;
  std::int64_t last = first;
  for (int i = 1; i <= 300; ++i) {
    const std::int64_t t = odd.Decide(0, 100).deliver_ns;
    EXPECT_NEAR(static_cast<double>(t - last), 800.0 / 3e6 * 1e9, 1.0);
    last = t;
  }
}

TEST(ImpairmentModel, RateDoesNotQueuePacketsSlowerThanTheLink) {
  ImpairmentModel model(ImpairmentSpec::Parse("rate=20mbit,delay=2ms"));
  for (std::int64_t i = 0; i < 1000; ++i) {
    const std::int64_t arrival = i * kMs;  // 1 ms apart, 400 us on the link
    EXPECT_EQ(model.Decide(arrival, 1000).deliver_ns, arrival + 400 * kUs + 2 * kMs);
  }
}

TEST(ImpairmentModel, RateQueueTailDropsBeyondLimit) {
  // 125 bytes at 1 Mbit/s = 1 ms each; the queue holds 10.
  ImpairmentModel model(ImpairmentSpec::Parse("rate=1mbit,limit=10"));
  std::size_t accepted = 0, dropped = 0;
  for (int i = 0; i < 100; ++i) {
    const PacketDecision d = model.Decide(0, 125);
    if (d.fate == PacketFate::kDelivered) {
      ++accepted;
      EXPECT_EQ(d.deliver_ns, static_cast<std::int64_t>(accepted) * kMs);
    } else {
      EXPECT_EQ(d.fate, PacketFate::kDroppedQueue);
      ++dropped;
    }
  }
  EXPECT_EQ(accepted, 10u);
  EXPECT_EQ(dropped, 90u);
  // At 5 ms five have left the link: five more fit, queued behind the link's backlog.
  for (int i = 0; i < 5; ++i) {
    const PacketDecision d = model.Decide(5 * kMs, 125);
    ASSERT_EQ(d.fate, PacketFate::kDelivered);
    EXPECT_EQ(d.deliver_ns, (11 + i) * kMs);
  }
  EXPECT_EQ(model.Decide(5 * kMs, 125).fate, PacketFate::kDroppedQueue);
}

std::vector<PacketDecision> Decisions(const std::string& spec, std::size_t n) {
  ImpairmentModel model(ImpairmentSpec::Parse(spec));
  std::vector<PacketDecision> out;
  for (std::size_t i = 0; i < n; ++i) {
    out.push_back(model.Decide(static_cast<std::int64_t>(i) * 300 * kUs, 200 + i % 1000));
  }
  return out;
}

bool SameDecisions(const std::vector<PacketDecision>& a, const std::vector<PacketDecision>& b) {
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].fate != b[i].fate || a[i].copies != b[i].copies || a[i].reordered != b[i].reordered ||
        (a[i].copies > 0 && a[i].deliver_ns != b[i].deliver_ns)) {
      return false;
    }
  }
  return a.size() == b.size();
}

TEST(ImpairmentModel, SameSeedSameDecisionsDifferentSeedDifferent) {
  const std::string base =
      "delay=5ms,jitter=2ms,loss=5%,burst=3,reorder=5%,dup=5%,rate=10mbit,limit=20";
  const auto a = Decisions(base + ",seed=42", 20'000);
  const auto b = Decisions(base + ",seed=42", 20'000);
  const auto c = Decisions(base + ",seed=43", 20'000);
  EXPECT_TRUE(SameDecisions(a, b));
  EXPECT_FALSE(SameDecisions(a, c));
}

TEST(ImpairmentModel, RejectsOutOfRangeSpec) {
  ImpairmentSpec spec;
  spec.loss = 1.5;
  EXPECT_THROW(ImpairmentModel{spec}, std::invalid_argument);
  spec = {};
  spec.loss = 1.0;
  spec.burst_packets = 2.0;
  EXPECT_THROW(ImpairmentModel{spec}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Classification and statistics.

/// A datagram in the header layout of protocol versions 2 to 7 (28 bytes: "HTLP", u16 version, u8
/// type, u8 flags, u32 session, u64 sequence at 12, i64 send time at 20), which the relay still
/// classifies; the relay tests below read the sequence and send time back from its bytes.
std::vector<std::uint8_t> WireDatagram(std::uint8_t type, std::uint64_t sequence,
                                       std::int64_t send_time_ns, std::size_t size = 36) {
  std::vector<std::uint8_t> b(std::max<std::size_t>(size, 28), 0);  // header, then cut to size
  const std::uint32_t magic = 0x504C5448u;
  for (int i = 0; i < 4; ++i) b[i] = static_cast<std::uint8_t>(magic >> (8 * i));
  b[4] = 1;  // version, little-endian u16
  b[6] = type;
  for (int i = 0; i < 8; ++i) b[12 + i] = static_cast<std::uint8_t>(sequence >> (8 * i));
  for (int i = 0; i < 8; ++i) {
    b[20 + i] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(send_time_ns) >> (8 * i));
  }
  b.resize(size);
  return b;
}

std::uint64_t ReadU64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = v << 8 | p[i];
  return v;
}

TEST(ClassifyDatagram, ReadsTypeAfterMagicElseOther) {
  // This version's layout: "HT", the version, the type at offset 3.
  const MacKey key = MacKey::Generate();
  const wire::Datagram tool = wire::EncodeCompactToolState({}, wire::ToolStateMessage{}, key);
  EXPECT_EQ(ClassifyDatagram(tool.view()), int(wire::MessageType::kCompactToolState));
  EXPECT_EQ(ClassifyDatagram(tool.view().first(4)), int(wire::MessageType::kCompactToolState));
  EXPECT_EQ(ClassifyDatagram(tool.view().first(3)), 0);  // too short for the type byte
  wire::Datagram other_version = tool;
  other_version.bytes[wire::kHeaderVersionOffset] = wire::kProtocolVersion + 1;
  EXPECT_EQ(ClassifyDatagram(other_version.view()), 0);
  // The layout of versions 2 to 7: "HTLP", the type at offset 6.
  EXPECT_EQ(ClassifyDatagram(WireDatagram(1, 0, 0)), 1);
  EXPECT_EQ(ClassifyDatagram(WireDatagram(11, 0, 0, 7)), 11);
  EXPECT_EQ(ClassifyDatagram(WireDatagram(200, 0, 0)), 200);
  EXPECT_EQ(ClassifyDatagram(WireDatagram(0, 0, 0)), 0);
  EXPECT_EQ(ClassifyDatagram(WireDatagram(2, 0, 0, 6)), 0);  // too short for the type byte
  auto wrong = WireDatagram(2, 0, 0);
  wrong[0] = 'X';
  EXPECT_EQ(ClassifyDatagram(wrong), 0);
  const std::string text = "PLTH: the magic in the wrong byte order";
  EXPECT_EQ(
      ClassifyDatagram(std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size())),
      0);
}

TEST(ClassifyDatagram, MagicIsHtInByteOrderAndWasHtlp) {
  const wire::Datagram d = wire::EncodePing({}, {}, MacKey::Generate());
  EXPECT_EQ(std::string(d.bytes.begin(), d.bytes.begin() + 2), "HT");
  EXPECT_EQ(d.bytes[wire::kHeaderVersionOffset], wire::kProtocolVersion);
  const auto legacy = WireDatagram(3, 0, 0);
  EXPECT_EQ(std::string(legacy.begin(), legacy.begin() + 4), "HTLP");
}

TEST(MessageTypeName, NamesKnownTypesAndNumbersTheRest) {
  const char* expected[] = {"other", "tool_state",     "contact_model", "goodbye",
                            "hello", "welcome",        "reject",        "ping",
                            "pong",  "scene_fragment", "scene_nack",    "scene_manifest"};
  for (std::uint8_t t = 0; t < 12; ++t) EXPECT_EQ(MessageTypeName(t), expected[t]);
  // The names are the protocol's own (wire::ToString), so a new type is named without a change
  // here.
  EXPECT_EQ(MessageTypeName(12), "compact_contact_model");
  EXPECT_EQ(MessageTypeName(13), "node_poses");
  EXPECT_EQ(MessageTypeName(14), "compact_tool_state");
  EXPECT_EQ(MessageTypeName(15), "depth_field_fragment");
  EXPECT_EQ(MessageTypeName(16), "depth_field_nack");
  EXPECT_EQ(MessageTypeName(17), "type_17");
  EXPECT_EQ(MessageTypeName(255), "type_255");
}

TEST(DirectionStats, JsonHasTotalsAndOneObjectPerTypeSeen) {
  DirectionStats s;
  s.by_type[1].received = 10;
  s.by_type[1].forwarded = 9;
  s.by_type[0].received = 2;
  s.by_type[0].dropped_loss = 2;
  s.by_type[42].received = 1;
  s.by_type[42].forwarded = 1;
  const nlohmann::json j = s.ToJson();
  EXPECT_EQ(j["received"], 13);
  EXPECT_EQ(j["forwarded"], 10);
  EXPECT_EQ(j["dropped_loss"], 2);
  EXPECT_EQ(j["tool_state"]["received"], 10);
  EXPECT_EQ(j["other"]["dropped_loss"], 2);
  EXPECT_EQ(j["type_42"]["forwarded"], 1);
  EXPECT_FALSE(j.contains("contact_model"));
  EXPECT_EQ(j["dropped_unknown_source"], 0);
}

// ---------------------------------------------------------------------------------------------
// ht_relay as a process.

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// A fresh directory under the system's temporary directory, removed with everything in it when
// the test ends (also when an assertion returns early).
struct TempDir {
  TempDir() {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "ht_relay_test.XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path = pattern;
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
  std::filesystem::path operator/(const char* name) const { return path / name; }
  std::filesystem::path path;
};

// Starts ht_relay with `args`; its stderr goes to `stderr_path` when given.
pid_t SpawnRelay(const std::vector<std::string>& args, const std::string& stderr_path = "") {
  std::vector<std::string> all = {HT_RELAY_EXE};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (!stderr_path.empty()) {
    posix_spawn_file_actions_addopen(&actions, 2, stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
  }
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw std::runtime_error(std::string("cannot start ") + HT_RELAY_EXE);
  return pid;
}

// Exit status of `pid`, or -1 when it did not exit normally (or within `timeout_s`, then killed).
int WaitExit(pid_t pid, double timeout_s = 30.0) {
  const std::int64_t deadline = NowNs() + static_cast<std::int64_t>(timeout_s * 1e9);
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (NowNs() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// The port ht_relay wrote to `port_file`, waiting up to 10 s for it (0 when it never came).
std::uint16_t WaitForPort(const std::filesystem::path& port_file) {
  for (int i = 0; i < 1000; ++i) {
    if (std::filesystem::exists(port_file)) {
      return static_cast<std::uint16_t>(std::stoi(ReadFile(port_file)));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return 0;
}

TEST(HtRelayProcess, ImpairsBothDirectionsAndCountsWhatItForwards) {
  const TempDir dir;
  UdpSocket server(SocketAddress::Parse("127.0.0.1:0"));
  UdpSocket client(SocketAddress::Parse("127.0.0.1:0"));
  const std::string spec = "loss=10%,dup=5%,delay=5ms,seed=3";
  const pid_t pid =
      SpawnRelay({"--listen", "127.0.0.1:0", "--forward", server.local_address().ToString(),
                  "--impair", spec, "--port-file", (dir / "port").string(), "--stats",
                  (dir / "stats.json").string(), "--quiet"});
  const std::uint16_t port = WaitForPort(dir / "port");
  if (port == 0) ::kill(pid, SIGKILL);
  ASSERT_NE(port, 0) << "ht_relay wrote no port file";
  const SocketAddress relay = SocketAddress::Parse("127.0.0.1:" + std::to_string(port));

  constexpr int kSent = 2000;
  constexpr int kEchoes = 20;
  std::array<std::uint8_t, 2048> buffer{};
  int server_tool_states = 0, server_other = 0, echoes_sent = 0, client_replies = 0;
  std::int64_t min_latency_ns = INT64_MAX;
  std::uint64_t last_sequence = 0;
  bool in_order = true;
  auto drain = [&] {
    SocketAddress from;
    while (const auto n = server.ReceiveFrom(buffer, from)) {
      const std::uint8_t type = ClassifyDatagram(std::span(buffer.data(), *n));
      if (type != 1) {
        ++server_other;
        continue;
      }
      ++server_tool_states;
      const std::uint64_t sequence = ReadU64(&buffer[12]);
      const auto sent_ns = static_cast<std::int64_t>(ReadU64(&buffer[20]));
      min_latency_ns = std::min(min_latency_ns, NowNs() - sent_ns);
      if (sequence < last_sequence) in_order = false;  // equal: a duplicate
      last_sequence = sequence;
      if (echoes_sent < kEchoes && sequence % 50 == 0) {  // reply through the relay
        const auto reply = WireDatagram(2, sequence, NowNs(), 60);
        if (server.SendTo(reply, from)) ++echoes_sent;
      }
    }
    while (const auto n = client.ReceiveFrom(buffer, from)) {
      EXPECT_TRUE(from == relay) << from.ToString();
      if (ClassifyDatagram(std::span(buffer.data(), *n)) == 2) ++client_replies;
    }
  };

  const std::int64_t start = NowNs();
  for (int i = 1; i <= kSent; ++i) {
    ASSERT_TRUE(client.SendTo(WireDatagram(1, static_cast<std::uint64_t>(i), NowNs()), relay));
    drain();
    std::this_thread::sleep_until(std::chrono::steady_clock::time_point(
        std::chrono::nanoseconds(start + static_cast<std::int64_t>(i) * 500 * kUs)));
  }
  const std::string not_wire = "plain text, no magic";
  ASSERT_TRUE(client.SendTo(
      std::span(reinterpret_cast<const std::uint8_t*>(not_wire.data()), not_wire.size()), relay));
  // Everything in flight arrives 5 ms after it was sent; wait well past that.
  for (int i = 0; i < 50; ++i) {
    drain();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  drain();
  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  ASSERT_EQ(WaitExit(pid), 0) << "ht_relay should exit 0 on SIGTERM";

  const nlohmann::json stats = nlohmann::json::parse(ReadFile(dir / "stats.json"));
  EXPECT_TRUE(stats["final"].get<bool>());
  EXPECT_EQ(stats["spec"]["up"], "delay=5ms,loss=10%,dup=5%,seed=3");  // canonical order
  EXPECT_EQ(stats["spec"]["down"], "delay=5ms,loss=10%,dup=5%,seed=4") << "down uses seed + 1";
  const nlohmann::json& up = stats["up"];
  const nlohmann::json& down = stats["down"];

  // Up: every datagram reached the relay, and what the server got is what the relay sent.
  EXPECT_EQ(up["received"], kSent + 1);
  EXPECT_EQ(up["tool_state"]["received"], kSent);
  EXPECT_EQ(up["tool_state"]["forwarded"], server_tool_states);
  EXPECT_EQ(up["other"]["received"], 1);
  EXPECT_EQ(up["other"]["forwarded"], server_other);
  EXPECT_EQ(up["in_flight_at_exit"], 0);
  EXPECT_EQ(up["send_errors"], 0);
  for (const nlohmann::json* c : {&up, &up["tool_state"], &down}) {
    EXPECT_EQ((*c)["forwarded"].get<std::int64_t>(), (*c)["received"].get<std::int64_t>() -
                                                         (*c)["dropped_loss"].get<std::int64_t>() -
                                                         (*c)["dropped_queue"].get<std::int64_t>() +
                                                         (*c)["duplicated"].get<std::int64_t>())
        << c->dump();
  }
  // 10 % loss and 5 % duplication of 2000: far (> 6σ) from 0 and from twice the rate.
  const auto lost = up["tool_state"]["dropped_loss"].get<int>();
  EXPECT_GT(lost, 100);
  EXPECT_LT(lost, 300);
  const auto duplicated = up["tool_state"]["duplicated"].get<int>();
  EXPECT_GT(duplicated, 30);
  EXPECT_LT(duplicated, 150);
  EXPECT_EQ(up["bytes_in"], kSent * 36 + static_cast<int>(not_wire.size()));
  // Nothing leaves before its 5 ms delay, and a fixed delay keeps the order.
  EXPECT_GE(min_latency_ns, 5 * kMs);
  EXPECT_TRUE(in_order);

  // Down: the server's replies came back to the client through the relay.
  EXPECT_EQ(echoes_sent, kEchoes);
  EXPECT_EQ(down["contact_model"]["received"], echoes_sent);
  EXPECT_EQ(down["contact_model"]["forwarded"], client_replies);
  EXPECT_GT(client_replies, 0);
  EXPECT_EQ(down["dropped_unknown_source"], 0);
}

TEST(HtRelayProcess, DropsServerSideDatagramsFromOtherAddresses) {
  const TempDir dir;
  UdpSocket server(SocketAddress::Parse("127.0.0.1:0"));
  UdpSocket client(SocketAddress::Parse("127.0.0.1:0"));
  UdpSocket stranger(SocketAddress::Parse("127.0.0.1:0"));
  const pid_t pid = SpawnRelay(
      {"--listen", "127.0.0.1:0", "--forward", server.local_address().ToString(), "--port-file",
       (dir / "port").string(), "--stats", (dir / "stats.json").string(), "--quiet"});
  const std::uint16_t port = WaitForPort(dir / "port");
  if (port == 0) ::kill(pid, SIGKILL);
  ASSERT_NE(port, 0);
  const SocketAddress relay = SocketAddress::Parse("127.0.0.1:" + std::to_string(port));
  ASSERT_TRUE(client.SendTo(WireDatagram(4, 1, 0), relay));  // hello, no impairment
  std::array<std::uint8_t, 2048> buffer{};
  SocketAddress relay_server_side;
  bool got = false;
  for (int i = 0; i < 1000 && !got; ++i) {
    got = server.WaitReadable(10) && server.ReceiveFrom(buffer, relay_server_side).has_value();
  }
  ASSERT_TRUE(got);
  ASSERT_TRUE(stranger.SendTo(WireDatagram(2, 1, 0), relay_server_side));
  ASSERT_TRUE(server.SendTo(WireDatagram(5, 1, 0), relay_server_side));  // welcome
  SocketAddress from;
  got = false;
  for (int i = 0; i < 1000 && !got; ++i) {
    got = client.WaitReadable(10) && client.ReceiveFrom(buffer, from).has_value();
  }
  ASSERT_TRUE(got);
  EXPECT_EQ(ClassifyDatagram(std::span(buffer.data(), 36)), 5);
  ASSERT_EQ(::kill(pid, SIGINT), 0);
  ASSERT_EQ(WaitExit(pid), 0);
  const nlohmann::json stats = nlohmann::json::parse(ReadFile(dir / "stats.json"));
  EXPECT_EQ(stats["spec"]["up"], "none");
  EXPECT_EQ(stats["up"]["hello"]["forwarded"], 1);
  EXPECT_EQ(stats["down"]["welcome"]["forwarded"], 1);
  EXPECT_EQ(stats["down"]["dropped_unknown_source"], 1);
  EXPECT_FALSE(stats["down"].contains("contact_model"));
}

TEST(HtRelayProcess, StopsAfterDurationAndWritesFinalStats) {
  const TempDir dir;
  const pid_t pid = SpawnRelay({"--listen", "127.0.0.1:0", "--forward", "127.0.0.1:9", "--duration",
                                "0.2", "--stats", (dir / "stats.json").string(), "--impair-up",
                                "delay=1ms", "--impair-down", "rate=1mbit,seed=9", "--quiet"});
  ASSERT_EQ(WaitExit(pid), 0);
  const nlohmann::json stats = nlohmann::json::parse(ReadFile(dir / "stats.json"));
  EXPECT_TRUE(stats["final"].get<bool>());
  EXPECT_EQ(stats["spec"]["up"], "delay=1ms,seed=1");
  EXPECT_EQ(stats["spec"]["down"], "rate=1mbit,seed=9");
  EXPECT_GE(stats["elapsed_s"].get<double>(), 0.2);
}

TEST(HtRelayProcess, BadArgumentsExitTwoWithAClearMessage) {
  const TempDir dir;
  struct Case {
    std::vector<std::string> args;
    const char* message_part;
  };
  const std::vector<Case> cases = {
      {{"--listen", "127.0.0.1:0", "--forward", "127.0.0.1:9", "--impair", "loss=150%"},
       "loss='150%'"},
      {{"--listen", "127.0.0.1:0", "--forward", "127.0.0.1:9", "--impair-down", "wobble=1"},
       "wobble"},
      {{"--listen", "nowhere", "--forward", "127.0.0.1:9"}, "nowhere"},
      {{"--listen", "127.0.0.1:0", "--forward", "127.0.0.1:0"}, "--forward"},
      {{"--listen", "127.0.0.1:0"}, "--forward"},
      {{"--listen", "127.0.0.1:0", "--forward", "127.0.0.1:9", "--duration", "-1"}, "--duration"},
  };
  for (const Case& c : cases) {
    const std::string err = (dir / "stderr.txt").string();
    const pid_t pid = SpawnRelay(c.args, err);
    EXPECT_EQ(WaitExit(pid), 2) << c.args.back();
    const std::string message = ReadFile(err);
    EXPECT_NE(message.find(c.message_part), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace ht
