// Novint Falcon backend: wire frames, FTDI set-up values, firmware file checks and load, the
// delta kinematics (two routes to each number), motor-command saturation, and the whole
// FalconDevice over a fake transport that plays the Falcon's side of the USB link.

#include "master_station/falcon.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <mutex>
#include <numbers>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace ht::falcon {
namespace {

using namespace std::chrono_literals;

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Polls `done` every millisecond until it holds or `timeout` passes.
bool WaitUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

// A well-formed TMS320 8-bit boot table: key, 8 reserved words, entry point, one block of
// `words` 16-bit words of pseudo-random data, terminator.
std::vector<std::uint8_t> MakeBootImage(std::size_t words, unsigned seed = 7) {
  std::vector<std::uint8_t> image(2 + 16, 0x00);  // key, 8 reserved words
  image[0] = 0xAA;
  image[1] = 0x08;
  for (std::uint8_t b : {0x3F, 0x00, 0x02, 0x80}) image.push_back(b);  // entry point
  image.push_back(static_cast<std::uint8_t>(words & 0xFF));
  image.push_back(static_cast<std::uint8_t>(words >> 8));
  for (std::uint8_t b : {0x3F, 0x00, 0x02, 0x80}) image.push_back(b);  // destination
  std::mt19937 rng(seed);
  for (std::size_t k = 0; k < 2 * words; ++k) image.push_back(static_cast<std::uint8_t>(rng()));
  image.push_back(0x00);
  image.push_back(0x00);
  return image;
}

std::string WriteTempFile(const std::string& name, const std::vector<std::uint8_t>& bytes) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("falcon_test_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  return path.string();
}

// ---------------------------------------------------------------------------------------------
// The Falcon's side of the link
// ---------------------------------------------------------------------------------------------

struct FakeOptions {
  bool leading_zero_in_hello = true;           // some hosts see 0x00 before the reply
  std::optional<std::size_t> corrupt_echo_at;  // flip an echoed firmware byte
  std::size_t max_read_bytes = 64;             // split responses across reads when small
  bool noise_before_first_response = false;    // garbage on the line before the first frame
  std::array<int, 3> unhomed_offset_counts = {517, -311, 1203};  // encoders before homing
  double home_angle_rad = 60.0 * std::numbers::pi / 180.0;       // "all the way out"
};

// Plays the FTDI chip and the DSP: checks the boot-loader sequence and that the firmware bytes
// arrive in order, then answers each request frame with encoders computed from a simulated
// handle position by inverse kinematics, and home switches that close once homing mode is on
// and the handle has been pulled all the way out. Records every request.
class FakeFalconTransport final : public FalconTransport {
 public:
  explicit FakeFalconTransport(std::vector<std::uint8_t> image, FakeOptions options = {})
      : image_(std::move(image)), options_(options) {}

  void PurgeBuffers() override {
    std::lock_guard lock(mutex_);
    log_.push_back("purge");
    rx_.clear();
  }
  void SetBaudRate(int baud) override {
    std::lock_guard lock(mutex_);
    log_.push_back("baud " + std::to_string(baud));
    baud_ = baud;
    if (baud == kRunningBaud) {
      if (phase_ != Phase::kImage || received_ != image_.size()) {
        Fail("switched to the running rate before the whole image arrived");
      }
      phase_ = Phase::kRunning;
    }
  }
  void SetLineFormat8N1NoFlowControl() override {
    std::lock_guard lock(mutex_);
    log_.push_back("8N1");
  }
  void SetLatencyTimer(int latency_ms) override {
    std::lock_guard lock(mutex_);
    log_.push_back("latency " + std::to_string(latency_ms));
  }
  void SetDtr(bool high) override {
    std::lock_guard lock(mutex_);
    log_.push_back(high ? "dtr 1" : "dtr 0");
    // A low-to-high DTR edge at 9600 baud resets the DSP into its boot loader.
    if (high && !dtr_ && baud_ == kHandshakeBaud) phase_ = Phase::kHandshake;
    dtr_ = high;
  }
  void SetRts(bool high) override {
    std::lock_guard lock(mutex_);
    log_.push_back(high ? "rts 1" : "rts 0");
  }

  int Write(std::span<const std::uint8_t> bytes, int) noexcept override {
    std::lock_guard lock(mutex_);
    switch (phase_) {
      case Phase::kIdle:
        Fail("bytes written before the boot loader was entered");
        return static_cast<int>(bytes.size());
      case Phase::kHandshake: {
        const std::vector<std::uint8_t> hello = {0x0A, 0x43, 0x0D};
        if (std::vector<std::uint8_t>(bytes.begin(), bytes.end()) == hello) {
          if (options_.leading_zero_in_hello) rx_.push_back(0x00);
          for (std::uint8_t b : {0x0A, 0x44, 0x2C, 0x0D}) rx_.push_back(b);
        } else if (bytes.size() == 1 && bytes[0] == 'A' && !dtr_ && baud_ == kFirmwareBaud) {
          rx_.push_back('A');
          phase_ = Phase::kImage;
        } else {
          Fail("unexpected bytes during the handshake");
        }
        return static_cast<int>(bytes.size());
      }
      case Phase::kImage:
        for (std::uint8_t b : bytes) {
          if (received_ >= image_.size() || b != image_[received_]) {
            Fail("firmware byte " + std::to_string(received_) + " out of order");
          }
          const bool corrupt = options_.corrupt_echo_at && *options_.corrupt_echo_at == received_;
          rx_.push_back(corrupt ? static_cast<std::uint8_t>(b ^ 0x5A) : b);
          ++received_;
        }
        return static_cast<int>(bytes.size());
      case Phase::kRunning:
        Answer(bytes);
        return static_cast<int>(bytes.size());
    }
    return -1;
  }

  int Read(std::span<std::uint8_t> out, int) noexcept override {
    std::lock_guard lock(mutex_);
    const std::size_t n = std::min({out.size(), rx_.size(), options_.max_read_bytes});
    for (std::size_t k = 0; k < n; ++k) {
      out[k] = rx_.front();
      rx_.pop_front();
    }
    return static_cast<int>(n);
  }

  // ---- test side ----
  void SetHandle(const glm::dvec3& p_DH) {
    std::lock_guard lock(mutex_);
    p_DH_ = p_DH;
  }
  // From now on every exchange advances `clock` by step_ns and moves the handle along
  // p0 + t·v (t the simulated time): a hand at constant speed, independent of thread scheduling.
  void SetTrajectory(const glm::dvec3& p0, const glm::dvec3& v, std::int64_t step_ns,
                     std::atomic<std::int64_t>* clock) {
    std::lock_guard lock(mutex_);
    trajectory_p0_ = p0;
    trajectory_v_ = v;
    trajectory_step_ns_ = step_ns;
    trajectory_t_ns_ = clock->load();
    trajectory_clock_ = clock;
    p_DH_ = p0 + (trajectory_t_ns_ * 1e-9) * v;
  }
  std::vector<std::string> log() const {
    std::lock_guard lock(mutex_);
    return log_;
  }
  std::string error() const {
    std::lock_guard lock(mutex_);
    return error_;
  }
  std::size_t firmware_bytes_received() const {
    std::lock_guard lock(mutex_);
    return received_;
  }
  std::vector<FalconRequest> requests() const {
    std::lock_guard lock(mutex_);
    return requests_;
  }
  std::size_t request_count() const {
    std::lock_guard lock(mutex_);
    return requests_.size();
  }
  std::optional<FalconRequest> last_request() const {
    std::lock_guard lock(mutex_);
    if (requests_.empty()) return std::nullopt;
    return requests_.back();
  }
  int malformed_requests() const {
    std::lock_guard lock(mutex_);
    return malformed_requests_;
  }
  bool running() const {
    std::lock_guard lock(mutex_);
    return phase_ == Phase::kRunning;
  }

 private:
  enum class Phase { kIdle, kHandshake, kImage, kRunning };

  void Fail(const std::string& what) {
    if (error_.empty()) error_ = what;
  }

  void Answer(std::span<const std::uint8_t> frame) {
    FalconRequest request;
    if (!DecodeRequest(frame, request)) {
      ++malformed_requests_;
      return;
    }
    requests_.push_back(request);
    if (trajectory_clock_ != nullptr) {
      // Simulated time: each exchange is one step later, and the handle is where a hand moving
      // at constant speed is then; the device's clock reads the same simulated time.
      trajectory_t_ns_ += trajectory_step_ns_;
      trajectory_clock_->store(trajectory_t_ns_);
      p_DH_ = trajectory_p0_ + (trajectory_t_ns_ * 1e-9) * trajectory_v_;
    }
    MotorAngles theta{};
    if (!InverseKinematics(p_DH_, theta)) {
      Fail("simulated handle outside the reach");
      return;
    }
    FalconResponse response;
    for (int i = 0; i < 3; ++i) {
      if (request.homing_mode && theta[i] > options_.home_angle_rad) homed_mask_ |= 1u << i;
      const bool homed = (homed_mask_ >> i) & 1u;
      const double counts = std::round(MotorAngleToEncoder(theta[i])) +
                            (homed ? 0 : options_.unhomed_offset_counts[i]);
      response.encoder[i] = static_cast<std::int16_t>(counts);
    }
    response.homed_mask = homed_mask_;
    response.buttons = 0x5;
    if (options_.noise_before_first_response && !noise_sent_) {
      for (std::uint8_t b : {0x00, 0x3E, 0x41, 0x7F}) rx_.push_back(b);
      noise_sent_ = true;
    }
    std::array<std::uint8_t, kFrameSize> bytes{};
    EncodeResponse(response, bytes);
    rx_.insert(rx_.end(), bytes.begin(), bytes.end());
  }

  mutable std::mutex mutex_;
  std::vector<std::uint8_t> image_;
  FakeOptions options_;
  Phase phase_ = Phase::kIdle;
  int baud_ = 0;
  bool dtr_ = false;
  std::size_t received_ = 0;
  std::deque<std::uint8_t> rx_;
  std::vector<std::string> log_;
  std::string error_;
  glm::dvec3 p_DH_{0.0};
  glm::dvec3 trajectory_p0_{0.0}, trajectory_v_{0.0};
  std::int64_t trajectory_step_ns_ = 0, trajectory_t_ns_ = 0;
  std::atomic<std::int64_t>* trajectory_clock_ = nullptr;
  std::uint8_t homed_mask_ = 0;
  bool noise_sent_ = false;
  std::vector<FalconRequest> requests_;
  int malformed_requests_ = 0;
};

// A device over a fake; the test keeps a pointer to the fake the factory hands over.
struct Rig {
  FakeFalconTransport* fake = nullptr;
  std::unique_ptr<FalconDevice> device;
  std::string firmware_path;
};

Rig MakeRig(FakeOptions options = {}, FalconConfig config = {}) {
  Rig rig;
  const std::vector<std::uint8_t> image = MakeBootImage(300);
  rig.firmware_path = WriteTempFile("rig.bin", image);
  config.firmware_path = rig.firmware_path;
  auto holder = std::make_shared<FakeFalconTransport*>(nullptr);
  rig.device = std::make_unique<FalconDevice>(config, [image, options, holder] {
    auto fake = std::make_unique<FakeFalconTransport>(image, options);
    *holder = fake.get();
    return std::unique_ptr<FalconTransport>(std::move(fake));
  });
  rig.device->Open();
  rig.fake = *holder;
  return rig;
}

// Pulls the simulated handle all the way out and back to the centre until the device is homed.
bool Home(Rig& rig) {
  rig.fake->SetHandle({0.0, 0.0, 0.06});
  const auto deadline = std::chrono::steady_clock::now() + 2s;
  while (!rig.device->status().homed && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(2ms);
  }
  rig.fake->SetHandle({0.0, 0.0, 0.0});
  std::this_thread::sleep_for(10ms);
  return rig.device->status().homed;
}

// ∂p/∂θ by central differences of the forward kinematics (the route independent of
// HandleJacobian's implicit-function derivation).
glm::dmat3 FiniteDifferenceJacobian(const glm::dvec3& p_DH) {
  MotorAngles theta{};
  EXPECT_TRUE(InverseKinematics(p_DH, theta));
  constexpr double h = 1e-6;
  glm::dmat3 J(0.0);
  for (int j = 0; j < 3; ++j) {
    MotorAngles plus = theta, minus = theta;
    plus[j] += h;
    minus[j] -= h;
    glm::dvec3 p_plus = p_DH, p_minus = p_DH;
    EXPECT_TRUE(ForwardKinematics(plus, p_plus));
    EXPECT_TRUE(ForwardKinematics(minus, p_minus));
    J[j] = (p_plus - p_minus) / (2.0 * h);
  }
  return J;
}

// ---------------------------------------------------------------------------------------------
// Frames
// ---------------------------------------------------------------------------------------------

TEST(FalconFrames, RequestRoundTripsFieldByField) {
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> any16(-32768, 32767);
  for (int k = 0; k < 200; ++k) {
    FalconRequest in;
    for (auto& m : in.motor_command) m = static_cast<std::int16_t>(any16(rng));
    if (k < 3) in.motor_command = {static_cast<std::int16_t>(-32768), 32767, 0};
    in.leds = static_cast<std::uint8_t>((k % 8) << 1);
    in.homing_mode = (k % 2) == 1;
    std::array<std::uint8_t, kFrameSize> bytes{};
    EncodeRequest(in, bytes);
    FalconRequest out;
    ASSERT_TRUE(DecodeRequest(bytes, out));
    EXPECT_EQ(out.motor_command, in.motor_command);
    EXPECT_EQ(out.leds, in.leds);
    EXPECT_EQ(out.homing_mode, in.homing_mode);
  }
}

TEST(FalconFrames, RequestLayoutIsLeastSignificantNibbleFirstOffsetBy0x41) {
  FalconRequest in;
  in.motor_command = {0x1234, -2, 0};  // -2 = 0xFFFE
  in.leds = kLedGreen;
  in.homing_mode = true;
  std::array<std::uint8_t, kFrameSize> bytes{};
  EncodeRequest(in, bytes);
  const std::array<std::uint8_t, kFrameSize> expected = {
      '<',         0x41 + 4,  0x41 + 3,  0x41 + 2,  0x41 + 1,  // 0x1234
      0x41 + 14,   0x41 + 15, 0x41 + 15, 0x41 + 15,            // 0xFFFE
      0x41,        0x41,      0x41,      0x41,                 // 0
      0x41 + 0x03,                                             // homing | green
      0x41,        '>'};
  EXPECT_EQ(bytes, expected);
}

TEST(FalconFrames, ResponseRoundTripsFieldByField) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> any16(-32768, 32767);
  for (int k = 0; k < 128; ++k) {
    FalconResponse in;
    for (auto& e : in.encoder) e = static_cast<std::int16_t>(any16(rng));
    in.homed_mask = static_cast<std::uint8_t>(k % 8);
    in.buttons = static_cast<std::uint8_t>(k % 16);
    std::array<std::uint8_t, kFrameSize> bytes{};
    EncodeResponse(in, bytes);
    FalconResponse out;
    ASSERT_TRUE(DecodeResponse(bytes, out));
    EXPECT_EQ(out.encoder, in.encoder);
    EXPECT_EQ(out.homed_mask, in.homed_mask);
    EXPECT_EQ(out.buttons, in.buttons);
  }
}

TEST(FalconFrames, ResponseFlagByteCarriesButtonsLowAndHomedBitsHigh) {
  std::array<std::uint8_t, kFrameSize> bytes{};
  bytes.fill(0x41);
  bytes[0] = '<';
  bytes[15] = '>';
  bytes[13] = 0x41 + 0x75;  // homed 0b111, buttons 0b0101
  bytes[14] = 0x99;         // undocumented byte: ignored
  FalconResponse out;
  ASSERT_TRUE(DecodeResponse(bytes, out));
  EXPECT_EQ(out.homed_mask, 0x7);
  EXPECT_EQ(out.buttons, 0x5);
  EXPECT_EQ(out.encoder, (std::array<std::int16_t, 3>{0, 0, 0}));
}

TEST(FalconFrames, RejectsMalformedFramesAndLeavesTheOutputUntouched) {
  FalconResponse good;
  good.encoder = {10, -20, 30};
  std::array<std::uint8_t, kFrameSize> frame{};
  EncodeResponse(good, frame);
  FalconRequest good_request;
  std::array<std::uint8_t, kFrameSize> request_frame{};
  EncodeRequest(good_request, request_frame);

  const FalconResponse sentinel{{7, 7, 7}, 0x3, 0x1};
  auto rejected = [&](std::vector<std::uint8_t> bytes) {
    FalconResponse out = sentinel;
    const bool ok = DecodeResponse(bytes, out);
    if (!ok) EXPECT_EQ(out.encoder, sentinel.encoder);
    return !ok;
  };
  const std::vector<std::uint8_t> base(frame.begin(), frame.end());
  EXPECT_TRUE(rejected({}));
  EXPECT_TRUE(rejected(std::vector<std::uint8_t>(base.begin(), base.end() - 1)));  // 15 bytes
  auto longer = base;
  longer.push_back('>');
  EXPECT_TRUE(rejected(longer));  // 17 bytes
  auto bad_start = base;
  bad_start[0] = '[';
  EXPECT_TRUE(rejected(bad_start));
  auto bad_end = base;
  bad_end[15] = '<';
  EXPECT_TRUE(rejected(bad_end));
  auto low_nibble = base;
  low_nibble[5] = 0x40;
  EXPECT_TRUE(rejected(low_nibble));
  auto high_nibble = base;
  high_nibble[12] = 0x51;
  EXPECT_TRUE(rejected(high_nibble));
  auto bad_flags = base;
  bad_flags[13] = 0xC1;  // 0x80 set: more than 7 flag bits
  EXPECT_TRUE(rejected(bad_flags));
  EXPECT_FALSE(rejected(base));

  FalconRequest out_request;
  auto bad_request_flags = std::vector<std::uint8_t>(request_frame.begin(), request_frame.end());
  bad_request_flags[13] = 0x51;  // 0x10 is not a request flag
  EXPECT_FALSE(DecodeRequest(bad_request_flags, out_request));
  auto short_request = std::vector<std::uint8_t>(request_frame.begin(), request_frame.end() - 2);
  EXPECT_FALSE(DecodeRequest(short_request, out_request));
}

TEST(FalconFrames, AssemblerRecoversFramesFromASplitNoisyCorruptStream) {
  auto frame_of = [](std::int16_t e) {
    FalconResponse r;
    r.encoder = {e, static_cast<std::int16_t>(e + 1), static_cast<std::int16_t>(e + 2)};
    std::array<std::uint8_t, kFrameSize> b{};
    EncodeResponse(r, b);
    return std::vector<std::uint8_t>(b.begin(), b.end());
  };
  ResponseAssembler assembler;
  FalconResponse newest;
  // Noise, then frame 100 split in two pushes.
  std::vector<std::uint8_t> a = {0x00, 0x3E, 0x41};
  const auto f100 = frame_of(100);
  a.insert(a.end(), f100.begin(), f100.begin() + 7);
  EXPECT_FALSE(assembler.Push(a, newest));
  EXPECT_TRUE(assembler.Push(std::span(f100).subspan(7), newest));
  EXPECT_EQ(newest.encoder[0], 100);
  // A corrupt frame immediately followed by a good one.
  auto corrupt = frame_of(200);
  corrupt[3] = 0x20;
  const auto f300 = frame_of(300);
  std::vector<std::uint8_t> b = corrupt;
  b.insert(b.end(), f300.begin(), f300.end());
  EXPECT_TRUE(assembler.Push(b, newest));
  EXPECT_EQ(newest.encoder[0], 300);
  EXPECT_EQ(assembler.malformed_frames(), 1u);
  // Two frames in one push: the newest wins.
  std::vector<std::uint8_t> c = frame_of(400);
  const auto f500 = frame_of(500);
  c.insert(c.end(), f500.begin(), f500.end());
  EXPECT_TRUE(assembler.Push(c, newest));
  EXPECT_EQ(newest.encoder[0], 500);
}

// ---------------------------------------------------------------------------------------------
// FTDI set-up values
// ---------------------------------------------------------------------------------------------

TEST(FtdiBaud, DivisorsMatchTheLiteralsLibnifalconSends) {
  EXPECT_EQ(FtdiBaudDivisor(kHandshakeBaud).value, 0x4138);  // "Baud for 9600 is 0x4138"
  EXPECT_EQ(FtdiBaudDivisor(kHandshakeBaud).index, 0);
  EXPECT_EQ(FtdiBaudDivisor(kFirmwareBaud).value, 0x0015);  // "0x15 clock ticks per signal"
  EXPECT_EQ(FtdiBaudDivisor(kFirmwareBaud).index, 0);
  EXPECT_EQ(FtdiBaudDivisor(kRunningBaud).value, 0x0002);  // setNormalMode
  EXPECT_EQ(FtdiBaudDivisor(3000000).value, 0);
  EXPECT_EQ(FtdiBaudDivisor(2000000).value, 1);
  for (int baud : {300, 9600, 115200, 142857, 1500000}) {
    const FtdiBaudSetting s = FtdiBaudDivisor(baud);
    EXPECT_NEAR(s.actual_baud, baud, 0.03 * baud) << baud;
  }
  EXPECT_THROW(FtdiBaudDivisor(100), std::invalid_argument);
  EXPECT_THROW(FtdiBaudDivisor(4000000), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Kinematics
// ---------------------------------------------------------------------------------------------

TEST(FalconKinematics, EncoderScaleIsTheCapstanRatioOfAQuadratureWheel) {
  EXPECT_NEAR(EncoderToMotorAngle(0), 35.0 * std::numbers::pi / 180.0, 1e-15);
  // One motor turn (320 slots x 4) turns the arm by the shaft/arm diameter ratio.
  EXPECT_NEAR(EncoderToMotorAngle(1280) - EncoderToMotorAngle(0),
              2.0 * std::numbers::pi * 14.25 / 110.0, 1e-12);
  for (double counts : {-3000.0, -1.0, 0.0, 17.0, 2500.0}) {
    EXPECT_NEAR(MotorAngleToEncoder(EncoderToMotorAngle(counts)), counts, 1e-9);
  }
}

TEST(FalconKinematics, ForwardInvertsInverseOverTheWorkspace) {
  // Grid over the ±5 cm cube around the workspace centre. The central ±4 cm must all be
  // reachable; corners of the ±5 cm cube may fall outside the mechanism's reach.
  double max_error_m = 0.0;
  int reachable = 0, total = 0;
  for (int i = -5; i <= 5; ++i) {
    for (int j = -5; j <= 5; ++j) {
      for (int k = -5; k <= 5; ++k) {
        const glm::dvec3 p{0.01 * i, 0.01 * j, 0.01 * k};
        const bool inner = std::max({std::abs(i), std::abs(j), std::abs(k)}) <= 4;
        MotorAngles theta{};
        const bool ok = InverseKinematics(p, theta);
        ++total;
        if (inner) {
          ASSERT_TRUE(ok) << p.x << " " << p.y << " " << p.z;
        }
        if (!ok) continue;
        ++reachable;
        glm::dvec3 q(0.0);  // cold start from the centre
        ASSERT_TRUE(ForwardKinematics(theta, q)) << p.x << " " << p.y << " " << p.z;
        max_error_m = std::max(max_error_m, glm::length(q - p));
      }
    }
  }
  std::cout << "FK(IK(p)) over " << reachable << "/" << total
            << " reachable grid points of the ±5 cm cube: max error " << max_error_m << " m\n";
  EXPECT_LT(max_error_m, 1e-9);
  RecordProperty("fk_ik_max_error_m", std::to_string(max_error_m));
}

TEST(FalconKinematics, EncoderQuantisationMovesTheHandleByLessThanATenthOfAMillimetre) {
  double max_error_m = 0.0;
  for (int i = -4; i <= 4; ++i) {
    for (int j = -4; j <= 4; ++j) {
      for (int k = -4; k <= 4; ++k) {
        const glm::dvec3 p{0.01 * i, 0.01 * j, 0.01 * k};
        MotorAngles theta{};
        ASSERT_TRUE(InverseKinematics(p, theta));
        MotorAngles quantised{};
        for (int m = 0; m < 3; ++m) {
          quantised[m] = EncoderToMotorAngle(std::round(MotorAngleToEncoder(theta[m])));
        }
        glm::dvec3 q = p;
        ASSERT_TRUE(ForwardKinematics(quantised, q));
        max_error_m = std::max(max_error_m, glm::length(q - p));
      }
    }
  }
  std::cout << "encoder quantisation over the ±4 cm cube: max position error " << max_error_m
            << " m\n";
  EXPECT_LT(max_error_m, 1e-4);
}

TEST(FalconKinematics, JacobianMatchesFiniteDifferencesOfForwardKinematics) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> box(-0.04, 0.04);
  std::normal_distribution<double> gauss;
  double max_relative = 0.0;
  for (int n = 0; n < 100; ++n) {
    const glm::dvec3 p{box(rng), box(rng), box(rng)};
    glm::dmat3 J;
    ASSERT_TRUE(HandleJacobian(p, J));
    const glm::dmat3 J_fd = FiniteDifferenceJacobian(p);
    const glm::dvec3 F{gauss(rng), gauss(rng), gauss(rng)};
    const glm::dvec3 tau = TorquesForForce(J, F);
    const glm::dvec3 tau_fd = glm::transpose(J_fd) * F;
    max_relative = std::max(max_relative, glm::length(tau - tau_fd) / glm::length(tau_fd));
    // Virtual work: a small motor motion dθ moves the handle by dp with τ·dθ = F·dp.
    MotorAngles theta{};
    ASSERT_TRUE(InverseKinematics(p, theta));
    const glm::dvec3 dtheta{1e-7 * gauss(rng), 1e-7 * gauss(rng), 1e-7 * gauss(rng)};
    MotorAngles moved = {theta[0] + dtheta.x, theta[1] + dtheta.y, theta[2] + dtheta.z};
    glm::dvec3 q = p;
    ASSERT_TRUE(ForwardKinematics(moved, q));
    const double work = glm::dot(tau, dtheta);
    EXPECT_NEAR(work, glm::dot(F, q - p), 1e-4 * std::abs(work) + 1e-14);
  }
  std::cout << "Jacobian transpose vs finite differences: max relative error " << max_relative
            << "\n";
  EXPECT_LT(max_relative, 1e-5);
}

// ---------------------------------------------------------------------------------------------
// Motor commands
// ---------------------------------------------------------------------------------------------

TEST(FalconMotorCommands, BelowTheLimitTheyAreMinusTenThousandPerNewtonMetre) {
  const MotorCommands mc = TorquesToMotorCommands({0.01, -0.02, 0.03}, 10000);
  EXPECT_FALSE(mc.saturated);
  EXPECT_EQ(mc.command, (std::array<std::int16_t, 3>{-100, 200, -300}));
}

TEST(FalconMotorCommands, SaturationScalesTheWholeVectorAndKeepsTheDirection) {
  const glm::dvec3 tau{0.5, -2.0, 1.0};
  const MotorCommands mc = TorquesToMotorCommands(tau, 10000);
  EXPECT_TRUE(mc.saturated);
  EXPECT_EQ(mc.command, (std::array<std::int16_t, 3>{-2500, 10000, -5000}));
  // Direction: the commands stay parallel to -τ.
  const glm::dvec3 c{mc.command[0], mc.command[1], mc.command[2]};
  EXPECT_NEAR(glm::dot(glm::normalize(c), glm::normalize(-tau)), 1.0, 1e-9);
  std::mt19937 rng(13);
  std::normal_distribution<double> gauss(0.0, 3.0);
  for (int n = 0; n < 100; ++n) {
    const glm::dvec3 t{gauss(rng), gauss(rng), gauss(rng)};
    const MotorCommands m = TorquesToMotorCommands(t, 4000);
    const glm::dvec3 cm{m.command[0], m.command[1], m.command[2]};
    const int largest =
        std::max({std::abs(m.command[0]), std::abs(m.command[1]), std::abs(m.command[2])});
    EXPECT_LE(largest, 4000);
    if (m.saturated) {
      EXPECT_EQ(largest, 4000);
    }
    EXPECT_GT(glm::dot(glm::normalize(cm), glm::normalize(-t)), 1.0 - 1e-6);
  }
  const double nan = std::nan("");
  EXPECT_EQ(TorquesToMotorCommands({nan, 0.0, 0.0}, 10000).command,
            (std::array<std::int16_t, 3>{0, 0, 0}));
}

// ---------------------------------------------------------------------------------------------
// Firmware file and load
// ---------------------------------------------------------------------------------------------

TEST(FalconFirmware, MissingFileGivesAClearError) {
  try {
    ReadFirmwareFile("/nonexistent/novint_falcon.bin");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("/nonexistent/novint_falcon.bin"), std::string::npos) << what;
    EXPECT_NE(what.find("--falcon-firmware"), std::string::npos) << what;
  }
  try {
    ReadFirmwareFile("");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("--falcon-firmware"), std::string::npos) << what;
    EXPECT_NE(what.find("not shipped"), std::string::npos) << what;
  }
}

TEST(FalconFirmware, AcceptsOnlyWellFormedBootTables) {
  const auto image = MakeBootImage(300);
  EXPECT_EQ(ReadFirmwareFile(WriteTempFile("good.bin", image)), image);

  auto wrong_key = image;
  wrong_key[1] = 0x09;
  EXPECT_THROW(ReadFirmwareFile(WriteTempFile("key.bin", wrong_key)), std::runtime_error);
  const std::vector<std::uint8_t> truncated(image.begin(), image.begin() + 200);
  try {
    ReadFirmwareFile(WriteTempFile("short.bin", truncated));
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadFirmwareFile(WriteTempFile("empty.bin", {})), std::runtime_error);
  EXPECT_THROW(CheckFirmwareImage(std::vector<std::uint8_t>(kMaxFirmwareSize + 1, 0xAA), "big"),
               std::runtime_error);
}

TEST(FalconProtocol, LoadsTheFirmwareInOrderThroughTheBootLoader) {
  const auto image = MakeBootImage(300);  // 628 bytes: ten full 62-byte chunks and a part
  FakeFalconTransport fake(image);
  FalconProtocol protocol(fake);
  protocol.LoadFirmware(image);
  EXPECT_EQ(fake.error(), "");
  EXPECT_EQ(fake.firmware_bytes_received(), image.size());
  EXPECT_TRUE(fake.running());
  const std::vector<std::string> expected = {"purge",     "latency 16",   "baud 9600", "8N1",
                                             "rts 0",     "dtr 0",        "dtr 1",   // boot loader
                                             "dtr 0",     "baud 142857",             // image rate
                                             "latency 1", "baud 1500000", "purge"};  // running
  EXPECT_EQ(fake.log(), expected);

  FalconRequest request;
  request.motor_command = {1, -2, 3};
  request.homing_mode = true;
  FalconResponse response;
  EXPECT_EQ(protocol.Exchange(request, response, 5), ExchangeResult::kOk);
  ASSERT_TRUE(fake.last_request().has_value());
  EXPECT_EQ(fake.last_request()->motor_command, request.motor_command);
  EXPECT_TRUE(fake.last_request()->homing_mode);
}

TEST(FalconProtocol, AnEchoMismatchAbortsTheLoadNamingTheByte) {
  const auto image = MakeBootImage(300);
  FakeOptions options;
  options.corrupt_echo_at = 100;
  options.leading_zero_in_hello = false;
  FakeFalconTransport fake(image, options);
  FalconProtocol protocol(fake);
  try {
    protocol.LoadFirmware(image);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("byte 100"), std::string::npos) << e.what();
  }
}

TEST(FalconProtocol, ExchangeSurvivesSplitResponsesAndLineNoise) {
  const auto image = MakeBootImage(40);
  FakeOptions options;
  options.max_read_bytes = 5;
  options.noise_before_first_response = true;
  FakeFalconTransport fake(image, options);
  FalconProtocol protocol(fake);
  protocol.LoadFirmware(image);
  for (int n = 0; n < 10; ++n) {
    FalconResponse response;
    ASSERT_EQ(protocol.Exchange(FalconRequest{}, response, 5), ExchangeResult::kOk) << n;
    EXPECT_EQ(response.buttons, 0x5);
  }
}

// ---------------------------------------------------------------------------------------------
// The whole device
// ---------------------------------------------------------------------------------------------

TEST(FalconDevice, OpenWithoutFirmwareSaysWhatIsMissing) {
  bool factory_called = false;
  FalconDevice device(FalconConfig{}, [&] {
    factory_called = true;
    return std::unique_ptr<FalconTransport>();
  });
  try {
    device.Open();
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("--falcon-firmware"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(factory_called);
  DeviceState state;
  EXPECT_FALSE(device.ReadState(NowNs(), state));
}

TEST(FalconDevice, CapabilitiesAreThoseOfAThreeDofFalcon) {
  FalconDevice device(FalconConfig{});
  const DeviceCapabilities c = device.capabilities();
  EXPECT_EQ(c.dof_in, 3);
  EXPECT_EQ(c.dof_out, 3);
  EXPECT_NEAR(c.max_force_n, 8.9, 1e-12);
  EXPECT_EQ(c.max_torque_nm, 0.0);
  EXPECT_NEAR(c.workspace_half_extents_m.x, 0.0508, 1e-12);
}

TEST(FalconDevice, NoForceAndNoStateUntilAllThreeAxesAreHomed) {
  Rig rig = MakeRig();
  ASSERT_EQ(rig.fake->error(), "");
  // Not homed: the loop's force is not rendered and readings are refused (for 60 ms, and until the
  // device thread has sent a few requests: a loaded machine may run it late; at most 2 s).
  const auto start = std::chrono::steady_clock::now();
  DeviceState state;
  while ((std::chrono::steady_clock::now() < start + 60ms || rig.fake->requests().size() <= 5) &&
         std::chrono::steady_clock::now() < start + 2s) {
    EXPECT_TRUE(rig.device->WriteWrench({{3.0, -2.0, 1.0}, {0.0, 0.0, 0.0}}, NowNs()));
    EXPECT_FALSE(rig.device->ReadState(NowNs(), state));
    std::this_thread::sleep_for(1ms);
  }
  EXPECT_FALSE(rig.device->status().homed);
  const auto before = rig.fake->requests();
  ASSERT_GT(before.size(), 5u);
  for (const FalconRequest& r : before) {
    EXPECT_EQ(r.motor_command, (std::array<std::int16_t, 3>{0, 0, 0}));
    EXPECT_TRUE(r.homing_mode);
    EXPECT_EQ(r.leds, kLedRed);
  }
  // The homing motion closes the home switches; forces then appear.
  ASSERT_TRUE(Home(rig));
  bool forced = false;
  const auto deadline = std::chrono::steady_clock::now() + 2s;
  while (!forced && std::chrono::steady_clock::now() < deadline) {
    rig.device->WriteWrench({{3.0, -2.0, 1.0}, {0.0, 0.0, 0.0}}, NowNs());
    std::this_thread::sleep_for(1ms);
    const auto last = rig.fake->last_request();
    forced = last && last->motor_command != std::array<std::int16_t, 3>{0, 0, 0};
  }
  EXPECT_TRUE(forced);
  const auto last = rig.fake->last_request();
  ASSERT_TRUE(last.has_value());
  EXPECT_FALSE(last->homing_mode);
  EXPECT_EQ(last->leds, kLedGreen);
  EXPECT_TRUE(rig.device->ReadState(NowNs(), state));
  rig.device->Close();
}

TEST(FalconDevice, ReadStateFollowsTheHandleAndWriteWrenchReachesTheMotors) {
  Rig rig = MakeRig();
  ASSERT_TRUE(Home(rig));
  double max_position_error_m = 0.0;
  int checked_wrenches = 0;
  const auto start = std::chrono::steady_clock::now();
  for (int k = 0; k < 30; ++k) {  // 30 waypoints held 10 ms each: ~300 ms
    const double a = 2.0 * std::numbers::pi * k / 30.0;
    const glm::dvec3 p{0.03 * std::cos(a), 0.02 * std::sin(a), 0.025 * std::sin(2.0 * a)};
    rig.fake->SetHandle(p);
    const glm::dvec3 F{2.0 * std::cos(3.0 * a), 1.5, -2.0 * std::sin(a)};
    // Hold the waypoint for 10 ms, and on until the reading has arrived and a few requests
    // have been made from it (a loaded machine may delay the I/O thread).
    DeviceState state;
    std::size_t requests_at_match = 0;
    const auto hold_start = std::chrono::steady_clock::now();
    ASSERT_TRUE(WaitUntil(
        [&] {
          rig.device->WriteWrench({F, {0.0, 0.0, 0.0}}, NowNs());
          const bool match = rig.device->ReadState(NowNs(), state) &&
                             glm::length(state.X_MH.translation - kR_MD * p) < 1e-4;
          if (!match) {
            requests_at_match = 0;
          } else if (requests_at_match == 0) {
            requests_at_match = rig.fake->request_count();
          }
          return std::chrono::steady_clock::now() - hold_start >= 10ms && match &&
                 rig.fake->request_count() >= requests_at_match + 3;
        },
        500ms))
        << k;
    max_position_error_m =
        std::max(max_position_error_m, glm::length(state.X_MH.translation - kR_MD * p));
    EXPECT_EQ(state.X_MH.rotation, glm::dquat(1.0, 0.0, 0.0, 0.0));
    EXPECT_EQ(state.V_MH_M.angular, glm::dvec3(0.0));
    EXPECT_EQ(state.buttons, 0x5u);

    // The handle is set in D (the kinematics' frame) and read in M (+z up): p_M = kR_MD · p_D.
    // The motors get -10000 · (∂p_D/∂θ)ᵀ F_D with F_D = kR_MDᵀ F_M, the Jacobian taken by finite
    // differences here.
    const glm::dvec3 tau =
        glm::transpose(FiniteDifferenceJacobian(p)) * (glm::transpose(kR_MD) * F);
    const auto last = rig.fake->last_request();
    ASSERT_TRUE(last.has_value());
    for (int m = 0; m < 3; ++m) {
      const double expected = -kMotorCommandPerNm * tau[m];
      EXPECT_NEAR(last->motor_command[m], expected, 3.0 + 0.01 * std::abs(expected))
          << "waypoint " << k << " motor " << m;
    }
    ++checked_wrenches;
  }
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "device over the fake: " << checked_wrenches << " waypoints in " << elapsed_s
            << " s, max position error " << max_position_error_m << " m, "
            << rig.device->status().exchanges << " exchanges\n";
  EXPECT_LT(max_position_error_m, 1e-4);
  EXPECT_EQ(rig.fake->malformed_requests(), 0);
  EXPECT_EQ(rig.device->status().kinematics_faults, 0u);
  rig.device->Close();
}

TEST(FalconDevice, TheLoopSeesZUpAndYAwayFromTheUser) {
  // kR_MD is a proper rotation.
  EXPECT_NEAR(glm::determinant(kR_MD), 1.0, 1e-15);
  const glm::dmat3 identity = glm::transpose(kR_MD) * kR_MD;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) EXPECT_EQ(identity[i][j], i == j ? 1.0 : 0.0);
  }
  Rig rig = MakeRig();
  ASSERT_TRUE(Home(rig));
  struct Case {
    glm::dvec3 p_DH;  // handle set in the kinematics' frame (+y up, +z towards the user)
    glm::dvec3 p_MH;  // what the loop must read (+z up, +y away from the user)
  };
  const Case cases[] = {{{0.0, 0.02, 0.0}, {0.0, 0.0, 0.02}},   // lifted: up
                        {{0.0, 0.0, 0.02}, {0.0, -0.02, 0.0}},  // pulled towards the user
                        {{0.02, 0.0, 0.0}, {0.02, 0.0, 0.0}}};  // to the right
  for (const Case& c : cases) {
    rig.fake->SetHandle(c.p_DH);
    DeviceState state;
    ASSERT_TRUE(WaitUntil(
        [&] {
          return rig.device->ReadState(NowNs(), state) &&
                 glm::length(state.X_MH.translation - c.p_MH) < 1e-4;
        },
        500ms))
        << "handle at D " << c.p_DH.x << " " << c.p_DH.y << " " << c.p_DH.z;
  }
  // An upward force in M pushes the handle up in D: the motors get what (0, F, 0) in D needs.
  const glm::dvec3 p{0.0, 0.0, 0.0};
  rig.fake->SetHandle(p);
  const auto request_with_force = [&](const glm::dvec3& F_M) {
    std::optional<std::array<std::int16_t, 3>> command;
    EXPECT_TRUE(WaitUntil(
        [&] {
          rig.device->WriteWrench({F_M, {0.0, 0.0, 0.0}}, NowNs());
          const auto last = rig.fake->last_request();
          const glm::dvec3 tau =
              glm::transpose(FiniteDifferenceJacobian(p)) * (glm::transpose(kR_MD) * F_M);
          if (!last) return false;
          for (int m = 0; m < 3; ++m) {
            if (std::abs(last->motor_command[m] + kMotorCommandPerNm * tau[m]) >
                3.0 + 0.01 * std::abs(kMotorCommandPerNm * tau[m])) {
              return false;
            }
          }
          command = last->motor_command;
          return true;
        },
        500ms));
    return command;
  };
  const auto up = request_with_force({0.0, 0.0, 3.0});
  const auto towards_user = request_with_force({0.0, -3.0, 0.0});
  ASSERT_TRUE(up && towards_user);
  EXPECT_NE(*up, *towards_user);
  rig.device->Close();
}

// The simulated clock of the velocity test: the fake advances it one step per exchange.
std::atomic<std::int64_t> g_sim_clock_ns{0};
std::int64_t SimClockNs() noexcept { return g_sim_clock_ns.load(); }

TEST(FalconDevice, VelocityFollowsAHandleMovingAtConstantSpeed) {
  // The I/O thread's clock is the simulated one, advanced 1 ms per exchange by the fake while
  // it moves the handle at constant speed: the estimate does not depend on how the machine
  // schedules the threads (it used to read the wall clock and be skipped when stalled).
  g_sim_clock_ns.store(1'000'000'000);
  FalconConfig config;
  config.clock_ns = &SimClockNs;
  Rig rig = MakeRig({}, config);
  ASSERT_TRUE(Home(rig));
  const glm::dvec3 v_true{0.2, -0.1, 0.05};  // m/s
  const glm::dvec3 p0{-0.02, 0.01, -0.005};
  const std::int64_t t0 = g_sim_clock_ns.load();
  rig.fake->SetTrajectory(p0 - (t0 * 1e-9) * v_true, v_true, 1'000'000, &g_sim_clock_ns);
  // 20 simulated ms for the 100 Hz filter to settle, then 100 readings, one per simulated ms.
  const auto wait_for_time = [&](std::int64_t t_ns) {
    return WaitUntil([&] { return g_sim_clock_ns.load() >= t_ns; }, 5s);
  };
  ASSERT_TRUE(wait_for_time(t0 + 20'000'000));
  glm::dvec3 v_sum(0.0);
  int samples = 0;
  for (int k = 0; k < 100; ++k) {
    ASSERT_TRUE(wait_for_time(t0 + (21 + k) * 1'000'000LL));
    DeviceState state;
    if (rig.device->ReadState(g_sim_clock_ns.load(), state)) {
      v_sum += glm::transpose(kR_MD) * state.V_MH_M.linear;  // back into D, where v_true is
      ++samples;
    }
  }
  ASSERT_GT(samples, 90);
  const glm::dvec3 v_mean = v_sum / static_cast<double>(samples);
  std::cout << "velocity estimate " << v_mean.x << " " << v_mean.y << " " << v_mean.z << " m/s for "
            << v_true.x << " " << v_true.y << " " << v_true.z << "\n";
  // Deterministic now: the encoder quantization alone is left (a few %).
  EXPECT_LT(glm::length(v_mean - v_true), 0.05 * glm::length(v_true));
  rig.device->Close();
}

TEST(FalconDevice, RendersZeroWhenTheLoopStopsWritingOrSendsANonFiniteWrench) {
  FalconConfig config;
  config.wrench_timeout_s = 0.1;
  Rig rig = MakeRig({}, config);
  ASSERT_TRUE(Home(rig));
  const std::array<std::int16_t, 3> zero = {0, 0, 0};
  auto last_command = [&] {
    const auto last = rig.fake->last_request();
    return last ? last->motor_command : zero;
  };
  const Wrench push{{0.0, 0.0, 4.0}, {0.0, 0.0, 0.0}};
  rig.device->WriteWrench(push, NowNs());
  EXPECT_TRUE(WaitUntil([&] { return last_command() != zero; }, 80ms));
  // No more writes: once the wrench is older than wrench_timeout_s it is no longer rendered.
  std::this_thread::sleep_for(150ms);
  EXPECT_TRUE(WaitUntil([&] { return last_command() == zero; }, 200ms));

  rig.device->WriteWrench(push, NowNs());
  EXPECT_TRUE(WaitUntil([&] { return last_command() != zero; }, 80ms));
  // A non-finite wrench is refused and zero is rendered instead.
  const Wrench nan_wrench{{std::nan(""), 0.0, 0.0}, {0.0, 0.0, 0.0}};
  EXPECT_FALSE(rig.device->WriteWrench(nan_wrench, NowNs()));
  EXPECT_TRUE(WaitUntil([&] { return last_command() == zero; }, 80ms));

  rig.device->Close();
  DeviceState state;
  EXPECT_FALSE(rig.device->ReadState(NowNs(), state));
  EXPECT_FALSE(rig.device->WriteWrench(push, NowNs()));
}

TEST(FalconDevice, OpenThroughLibusbWithoutAFalconThrowsAClearMessage) {
  FalconConfig config;
  config.firmware_path = WriteTempFile("libusb.bin", MakeBootImage(40));
  FalconDevice device(config);  // default transport: libusb
  try {
    device.Open();
    FAIL() << "Open succeeded: is a Novint Falcon attached to this machine?";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    std::cout << "libusb Open: " << what << "\n";
    EXPECT_NE(what.find("Novint Falcon"), std::string::npos) << what;
    EXPECT_NE(what.find("0403:cb48"), std::string::npos) << what;
    EXPECT_NE(what.find("deploy/udev/70-haptic-falcon.rules"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace ht::falcon
