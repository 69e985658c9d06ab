/* drivecheck SITL shim: the shim's internal interfaces (our own code). */
#ifndef SITL_SHIM_H
#define SITL_SHIM_H
#include "ch.h"
#include <stdint.h>

/* scheduler (sitl_rt.c) */
uint64_t sitl_rt_now_us(void);
uint64_t sitl_rt_switches(void);
void sitl_rt_run_until(uint64_t target_us);
void sitl_rt_run_ready(void);

/* host link (sitl_io.c) */
_Noreturn void sitl_fatal(const char *msg);
void sitl_out_car_bytes(const unsigned char *data, unsigned int len);
void sitl_out_servo(float pos);
void sitl_out_motor(uint8_t kind, float value);
void sitl_out_uwb_request(uint8_t id, uint8_t dest, int32_t samples);
void sitl_out_note(const char *text);

/* hardware stand-ins (sitl_hw.c, sitl_fw.c) */
void sitl_hw_start(void);
void sitl_hw_imu_set(const float accel[3], const float gyro[3], const float mag[3]);
void sitl_hw_imu_noise(float accel_sd, float gyro_sd, uint64_t seed);
void sitl_hw_car_bytes(const unsigned char *data, unsigned int len);
void sitl_hw_nmea(const char *line, unsigned int len);
void sitl_hw_pps(void);
void sitl_hw_uwb_range(uint8_t id, uint8_t dest, float range);
void sitl_hw_motor_values(const float values[6]);
float sitl_fw_board_yaw_rot_deg(void);
float sitl_fw_steering_ramp_time(void);
void sitl_hw_servo_start(void);
#endif
