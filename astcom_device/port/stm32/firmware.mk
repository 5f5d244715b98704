# The example controller for QEMU's netduinoplus2 (STM32F405, Cortex-M4F), with Debian's
# gcc-arm-none-eabi and newlib. libmpack and mbedTLS are compiled from Debian's source
# packages (setup/50-device.sh unpacks them into $(BUILD)/deb-src); the msgpack-c packer
# and the libmpack header are the architecture-independent headers of the Debian packages.
ARM_CC := arm-none-eabi-gcc
ARM_SIZE := arm-none-eabi-size
DEBSRC := $(BUILD)/deb-src
ARM_DIR := $(BUILD)/arm
FIRMWARE_PASSWORD ?= op-secret
# Our sources build with -Werror; Debian's (mbedTLS, libmpack) with their warnings off, in
# objects of their own, so that -w never silences ours. -flto lets the linker drop and fold
# across files; newlib-nano without its float printf (the library formats with ad_snprintf).
# FW_ARENA_BYTES and FW_LINK_BYTES are what ad_arena_bytes() and ad_link_bytes() say for
# board.c's configuration (the QEMU test reads them from the running firmware and fails
# when they differ); the firmware reports a too small arena on its UART at boot.
ARM_CPU := -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16
ARM_COMMON := $(ARM_CPU) -Os -flto=auto -ffunction-sections -fdata-sections -std=c99 \
  '-DMBEDTLS_CONFIG_FILE="mbedtls_config_m4.h"'
ARM_FLAGS := $(ARM_COMMON) -Wall -Wextra -Werror -Wno-unused-parameter -DEX_MCU -DAD_NO_FORMAT_CHECK \
  -DEX_TRAJ_CAPACITY=48 -DAD_LINK_TX_FRAMES=1u -DAD_LINK_PARK_FRAMES=0u -DFIRMWARE_PASSWORD='"$(FIRMWARE_PASSWORD)"' \
  -DFW_ARENA_BYTES=21168u -DFW_LINK_BYTES=3360u -DFW_MBEDTLS_BYTES=512u -DAD_WHY_BYTES=320
ARM_INC := -Iinclude -Isrc -Iexamples -Iport/stm32 -I$(ARM_DIR)/include -I$(DEBSRC)/mbedtls/include
MBEDTLS_SRC := $(addprefix $(DEBSRC)/mbedtls/library/,md.c sha256.c platform.c platform_util.c memory_buffer_alloc.c)
MPACK_SRC := $(DEBSRC)/libmpack/src/core.c $(DEBSRC)/libmpack/src/conv.c
FW_SRC := $(LIB_SRC) examples/example_controller.c port/stm32/board.c port/stm32/startup.c
DEB_OBJ := $(patsubst $(DEBSRC)/%.c,$(ARM_DIR)/deb/%.o,$(MBEDTLS_SRC) $(MPACK_SRC))

.PHONY: arm size qemu-check
arm: $(ARM_DIR)/example.elf

$(ARM_DIR)/include/.done:
	@test -d $(DEBSRC)/mbedtls -a -d $(DEBSRC)/libmpack || { echo "run: bash setup/50-device.sh (Debian sources for the firmware)"; exit 1; }
	mkdir -p $(ARM_DIR)/include
	ln -sf /usr/include/mpack.h /usr/include/msgpack.h /usr/include/msgpack $(ARM_DIR)/include/
	touch $@

$(ARM_DIR)/deb/%.o: $(DEBSRC)/%.c port/stm32/mbedtls_config_m4.h $(ARM_DIR)/include/.done port/stm32/firmware.mk
	@mkdir -p $(@D)
	$(ARM_CC) $(ARM_COMMON) -w $(ARM_INC) -c $< -o $@

$(ARM_DIR)/example.elf: $(FW_SRC) $(HEADERS) $(DEB_OBJ) port/stm32/stm32f405.ld Makefile port/stm32/firmware.mk
	$(ARM_CC) $(ARM_FLAGS) $(ARM_INC) $(FW_SRC) $(DEB_OBJ) \
	  -Tport/stm32/stm32f405.ld -nostartfiles --specs=nano.specs --specs=nosys.specs \
	  -Wl,--gc-sections -Wl,-Map=$(ARM_DIR)/example.map -lm -o $@

size: $(ARM_DIR)/example.elf
	$(ARM_SIZE) -A $< | grep -E '^\.(text|ARM|data|bss|stack) '
	$(ARM_SIZE) $<
