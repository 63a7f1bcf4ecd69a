// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// MPU-6000 register map, bit definitions and FIFO layout.
//
// Source: InvenSense "MPU-6000 and MPU-6050 Register Map and Descriptions", RM-MPU-6000A-00
// rev 4.2 (cited below as RM), and "MPU-6000 and MPU-6050 Product Specification",
// PS-MPU-6000A-00 rev 3.4 (cited as PS). The offset registers 0x06-0x0B and 0x13-0x18 are not in
// RM rev 4.2; they follow InvenSense's "MPU Hardware Offset Registers" application note and are
// the same on every MPU-6000/6050 part.

#include <cstdint>

namespace imucal::drivers::mpu6000 {

constexpr std::uint8_t Bit0 = 1u << 0;
constexpr std::uint8_t Bit1 = 1u << 1;
constexpr std::uint8_t Bit2 = 1u << 2;
constexpr std::uint8_t Bit3 = 1u << 3;
constexpr std::uint8_t Bit4 = 1u << 4;
constexpr std::uint8_t Bit5 = 1u << 5;
constexpr std::uint8_t Bit6 = 1u << 6;
constexpr std::uint8_t Bit7 = 1u << 7;

/// WHO_AM_I reset value (RM 4.32).
constexpr std::uint8_t WHOAMI = 0x68;

/// SPI: all registers at up to 1 MHz, sensor and interrupt registers at up to 20 MHz (PS 6.5).
constexpr std::uint32_t kSpiConfigSpeedHz = 1'000'000;
constexpr std::uint32_t kSpiSensorSpeedHz = 20'000'000;
/// I2C fast mode (PS 6.5).
constexpr std::uint32_t kI2cSpeedHz = 400'000;

/// FIFO buffer size in bytes (RM 4.30, PS 7.17).
constexpr std::uint16_t kFifoSizeBytes = 1024;

/// Internal gyro output rate: 8 kHz with the DLPF off (DLPF_CFG 0 or 7), 1 kHz otherwise;
/// the accelerometer always outputs 1 kHz (RM 4.2, 4.3).
constexpr std::uint32_t kGyroRateDlpfOffHz = 8000;
constexpr std::uint32_t kGyroRateDlpfOnHz = 1000;
constexpr std::uint32_t kAccelRateHz = 1000;

/// Temperature in deg C = TEMP_OUT / 340 + 36.53 (RM 4.18).
constexpr double kTempLsbPerDegC = 340.0;
constexpr double kTempOffsetDegC = 36.53;

enum class Register : std::uint8_t {
  XA_OFFS_H = 0x06,  // accel offsets: int16, +-16 g scale (2048 LSB/g), bit 0 of _L reserved
  XA_OFFS_L_TC = 0x07,
  YA_OFFS_H = 0x08,
  YA_OFFS_L_TC = 0x09,
  ZA_OFFS_H = 0x0A,
  ZA_OFFS_L_TC = 0x0B,

  SELF_TEST_X = 0x0D,
  SELF_TEST_Y = 0x0E,
  SELF_TEST_Z = 0x0F,
  SELF_TEST_A = 0x10,

  XG_OFFS_USRH = 0x13,  // gyro offsets: int16, +-1000 dps scale (32.8 LSB/dps)
  XG_OFFS_USRL = 0x14,
  YG_OFFS_USRH = 0x15,
  YG_OFFS_USRL = 0x16,
  ZG_OFFS_USRH = 0x17,
  ZG_OFFS_USRL = 0x18,

  SMPLRT_DIV = 0x19,
  CONFIG = 0x1A,
  GYRO_CONFIG = 0x1B,
  ACCEL_CONFIG = 0x1C,

  FIFO_EN = 0x23,

  INT_PIN_CFG = 0x37,
  INT_ENABLE = 0x38,
  INT_STATUS = 0x3A,

  ACCEL_XOUT_H = 0x3B,
  ACCEL_XOUT_L = 0x3C,
  ACCEL_YOUT_H = 0x3D,
  ACCEL_YOUT_L = 0x3E,
  ACCEL_ZOUT_H = 0x3F,
  ACCEL_ZOUT_L = 0x40,
  TEMP_OUT_H = 0x41,
  TEMP_OUT_L = 0x42,
  GYRO_XOUT_H = 0x43,
  GYRO_XOUT_L = 0x44,
  GYRO_YOUT_H = 0x45,
  GYRO_YOUT_L = 0x46,
  GYRO_ZOUT_H = 0x47,
  GYRO_ZOUT_L = 0x48,

  SIGNAL_PATH_RESET = 0x68,
  USER_CTRL = 0x6A,
  PWR_MGMT_1 = 0x6B,
  PWR_MGMT_2 = 0x6C,

  FIFO_COUNTH = 0x72,
  FIFO_COUNTL = 0x73,
  FIFO_R_W = 0x74,
  WHO_AM_I = 0x75,
};

constexpr std::uint8_t reg_addr(Register r) { return static_cast<std::uint8_t>(r); }

// SELF_TEST_X/Y/Z (RM 4.1): XA_TEST[4:2] in bits 7:5, XG_TEST[4:0] in bits 4:0.
enum SELF_TEST_XYZ_BIT : std::uint8_t {
  A_TEST_HI = Bit7 | Bit6 | Bit5,
  G_TEST = Bit4 | Bit3 | Bit2 | Bit1 | Bit0,
};

// SELF_TEST_A (RM 4.1): XA_TEST[1:0] bits 5:4, YA_TEST[1:0] bits 3:2, ZA_TEST[1:0] bits 1:0.
enum SELF_TEST_A_BIT : std::uint8_t {
  XA_TEST_LO = Bit5 | Bit4,
  YA_TEST_LO = Bit3 | Bit2,
  ZA_TEST_LO = Bit1 | Bit0,
};

// CONFIG (RM 4.3)
enum CONFIG_BIT : std::uint8_t {
  EXT_SYNC_SET = Bit5 | Bit4 | Bit3,  // 0: FSYNC input disabled
  DLPF_CFG = Bit2 | Bit1 | Bit0,      // 0: 260/256 Hz (gyro 8 kHz); 1..6: 184..5 Hz (gyro 1 kHz)
};

// GYRO_CONFIG (RM 4.4)
enum GYRO_CONFIG_BIT : std::uint8_t {
  XG_ST = Bit7,
  YG_ST = Bit6,
  ZG_ST = Bit5,
  FS_SEL = Bit4 | Bit3,  // 0: 250, 1: 500, 2: 1000, 3: 2000 dps
};

// ACCEL_CONFIG (RM 4.5)
enum ACCEL_CONFIG_BIT : std::uint8_t {
  XA_ST = Bit7,
  YA_ST = Bit6,
  ZA_ST = Bit5,
  AFS_SEL = Bit4 | Bit3,  // 0: 2, 1: 4, 2: 8, 3: 16 g
};

// FIFO_EN (RM 4.7)
enum FIFO_EN_BIT : std::uint8_t {
  TEMP_FIFO_EN = Bit7,
  XG_FIFO_EN = Bit6,
  YG_FIFO_EN = Bit5,
  ZG_FIFO_EN = Bit4,
  ACCEL_FIFO_EN = Bit3,
  SLV2_FIFO_EN = Bit2,
  SLV1_FIFO_EN = Bit1,
  SLV0_FIFO_EN = Bit0,
};

// INT_PIN_CFG (RM 4.15)
enum INT_PIN_CFG_BIT : std::uint8_t {
  INT_LEVEL = Bit7,     // 1: active low
  INT_OPEN = Bit6,      // 1: open drain
  LATCH_INT_EN = Bit5,  // 0: 50 us pulse
  INT_RD_CLEAR = Bit4,  // 0: status cleared only by reading INT_STATUS
  FSYNC_INT_LEVEL = Bit3,
  FSYNC_INT_EN = Bit2,
  I2C_BYPASS_EN = Bit1,
};

// INT_ENABLE (RM 4.16)
enum INT_ENABLE_BIT : std::uint8_t {
  FIFO_OFLOW_EN = Bit4,
  I2C_MST_INT_EN = Bit3,
  DATA_RDY_EN = Bit0,
};

// INT_STATUS (RM 4.17), cleared by reading it.
enum INT_STATUS_BIT : std::uint8_t {
  FIFO_OFLOW_INT = Bit4,
  I2C_MST_INT = Bit3,
  DATA_RDY_INT = Bit0,
};

// SIGNAL_PATH_RESET (RM 4.26)
enum SIGNAL_PATH_RESET_BIT : std::uint8_t {
  GYRO_RESET = Bit2,
  ACCEL_RESET = Bit1,
  TEMP_RESET = Bit0,
};

// USER_CTRL (RM 4.27)
enum USER_CTRL_BIT : std::uint8_t {
  FIFO_EN = Bit6,
  I2C_MST_EN = Bit5,
  I2C_IF_DIS = Bit4,  // SPI only: disables the I2C interface
  FIFO_RESET = Bit2,  // self-clearing
  I2C_MST_RESET = Bit1,
  SIG_COND_RESET = Bit0,
};

// PWR_MGMT_1 (RM 4.28), reset value 0x40 (SLEEP).
enum PWR_MGMT_1_BIT : std::uint8_t {
  DEVICE_RESET = Bit7,  // self-clearing
  SLEEP = Bit6,
  CYCLE = Bit5,
  TEMP_DIS = Bit3,
  CLKSEL = Bit2 | Bit1 | Bit0,
  CLKSEL_PLL_GYRO_X = Bit0,  // CLKSEL = 1: PLL with X-axis gyro reference (recommended, RM 4.28)
};
constexpr std::uint8_t kPwrMgmt1ResetValue = SLEEP;

// PWR_MGMT_2 (RM 4.29)
enum PWR_MGMT_2_BIT : std::uint8_t {
  LP_WAKE_CTRL = Bit7 | Bit6,
  STBY_XA = Bit5,
  STBY_YA = Bit4,
  STBY_ZA = Bit3,
  STBY_XG = Bit2,
  STBY_YG = Bit1,
  STBY_ZG = Bit0,
};

enum class AccelRange : std::uint8_t { k2g = 0, k4g = 1, k8g = 2, k16g = 3 };
enum class GyroRange : std::uint8_t { k250dps = 0, k500dps = 1, k1000dps = 2, k2000dps = 3 };

constexpr int accel_full_scale_g(AccelRange r) { return 2 << static_cast<int>(r); }
constexpr int gyro_full_scale_dps(GyroRange r) { return 250 << static_cast<int>(r); }
/// Sensitivity, RM 4.17: 16384 / 2^AFS_SEL LSB/g.
constexpr double accel_lsb_per_g(AccelRange r) {
  return 16384.0 / static_cast<double>(1 << static_cast<int>(r));
}
/// Sensitivity, RM 4.19: 131, 65.5, 32.8, 16.4 LSB/(deg/s) (the datasheet's rounded figures).
constexpr double gyro_lsb_per_dps(GyroRange r) {
  constexpr double kLsbPerDps[4] = {131.0, 65.5, 32.8, 16.4};
  return kLsbPerDps[static_cast<int>(r) & 3];
}

/// Offset register scales (offset application note): accel at +-16 g, gyro at +-1000 dps.
constexpr double kAccelOffsetLsbPerG = 2048.0;
constexpr double kGyroOffsetLsbPerDps = 32.8;
/// Output counts one gyro offset register count adds at range r: the register counts
/// 1 / kGyroOffsetLsbPerDps deg/s whatever the range, which is 4 output counts at +-250 deg/s, 2
/// at +-500, 1 at +-1000 and 1/2 at +-2000 (the chip scales by powers of two; the datasheet's
/// rounded sensitivities, 131 / 32.8, give 3.99).
constexpr double gyro_output_counts_per_offset_count(GyroRange r) {
  return 4.0 / static_cast<double>(1 << (static_cast<int>(r) & 3));
}

/// Low-pass filter bandwidths per DLPF_CFG 0..6 (RM 4.3), accel / gyro in Hz.
constexpr int kDlpfAccelBandwidthHz[7] = {260, 184, 94, 44, 21, 10, 5};
constexpr int kDlpfGyroBandwidthHz[7] = {256, 188, 98, 42, 20, 10, 5};

namespace FIFO {
/// One FIFO frame with FIFO_EN = ACCEL | TEMP | XG | YG | ZG: registers 0x3B..0x48 in register
/// order (RM 4.7), every value big-endian.
struct DATA {
  std::uint8_t ACCEL_XOUT_H, ACCEL_XOUT_L;
  std::uint8_t ACCEL_YOUT_H, ACCEL_YOUT_L;
  std::uint8_t ACCEL_ZOUT_H, ACCEL_ZOUT_L;
  std::uint8_t TEMP_OUT_H, TEMP_OUT_L;
  std::uint8_t GYRO_XOUT_H, GYRO_XOUT_L;
  std::uint8_t GYRO_YOUT_H, GYRO_YOUT_L;
  std::uint8_t GYRO_ZOUT_H, GYRO_ZOUT_L;
} __attribute__((packed));
static_assert(sizeof(DATA) == 14, "MPU-6000 FIFO frame must be 14 bytes");
constexpr std::uint16_t kFrameBytes = sizeof(DATA);
}  // namespace FIFO

constexpr std::int16_t be16(std::uint8_t hi, std::uint8_t lo) {
  return static_cast<std::int16_t>(static_cast<std::uint16_t>((hi << 8) | lo));
}

}  // namespace imucal::drivers::mpu6000
